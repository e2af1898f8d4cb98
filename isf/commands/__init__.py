"""Subcommands of the ``isf`` command line, one module each.

Each module defines ``add_parser(subparsers)``, which adds the subcommand's parser and sets its
``run`` default to a function ``run(args) -> int`` that returns the exit code (see
:mod:`isf.cli`). :data:`isf.cli.COMMAND_MODULES` lists the modules. ``add_parser`` is called at
every start of ``isf``: a module imports only the standard library at its top, and the rest of
isf inside ``run``, so that ``isf --help`` stays fast.
"""
