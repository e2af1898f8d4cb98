"""Sphinx configuration of the isf documentation.

Build (strict: any warning fails the build)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html

Pages are Markdown (MyST); the API reference is generated from the Google-style
docstrings (autodoc + napoleon) and the CLI reference from the argparse parser
of ``isf.cli`` (the ``isf-cli`` directive defined below), so neither can drift
from the code. No network access is needed: intersphinx is deliberately off.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib
import inspect
import re
import sys
import textwrap
from pathlib import Path

from docutils import nodes
from sphinx.util import logging as sphinx_logging
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[1]
if (ROOT / "isf" / "__init__.py").is_file():
    sys.path.insert(0, str(ROOT))  # document this checkout even when another isf is installed

import isf  # noqa: E402  (after the path tweak)

# -- project -----------------------------------------------------------------------------------
project = "isf"
author = "isf developers"
copyright = "isf developers, Apache-2.0"
release = isf.__version__
version = ".".join(release.split(".")[:2])

# -- general -----------------------------------------------------------------------------------
extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
language = "en"

# Strict cross-references. Every ``py:`` reference (including the types that autodoc
# writes for annotations) must resolve to something documented here.
nitpicky = True

# intersphinx is off (builds run offline), so references to other projects' objects can
# never resolve. They are ignored by *module prefix*; a reference to ``isf.*`` is never
# ignored, so a broken isf reference still fails the build.
_THIRD_PARTY_MODULES = (
    # isf's runtime dependencies, as imported and as aliased in string annotations
    "numpy", "np", "scipy", "pinocchio", "pin", "coal", "trimesh", "yourdfpy", "osqp",
    # Python's standard library (builtins and typing names Sphinx resolves by itself)
    "pathlib", "collections.abc", "enum", "abc",
)
nitpick_ignore_regex = [
    (r"py:.*", r"({})\..+".format("|".join(m.replace(".", r"\.") for m in _THIRD_PARTY_MODULES))),
]
nitpick_ignore = [
    ("py:class", "Path"),  # pathlib.Path as string annotations name it (intersphinx is off)
]

# -- MyST --------------------------------------------------------------------------------------
myst_enable_extensions: list[str] = []  # plain CommonMark + MyST roles/directives; no `$` math
myst_heading_anchors = 3  # `[text](page.md#a-heading)` links resolve to generated anchors

# -- autodoc / napoleon ------------------------------------------------------------------------
autodoc_default_options = {
    "members": True,
    "member-order": "bysource",
    "show-inheritance": True,
}
autodoc_typehints = "description"     # types go into the parameter list, signatures stay short
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True      # defaults as written in the source, not their repr()
autoclass_content = "class"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_attr_annotations = True

# -- HTML --------------------------------------------------------------------------------------
try:
    import furo  # noqa: F401

    html_theme = "furo"
except ImportError:  # the builtin theme keeps the build working without furo
    html_theme = "alabaster"
html_title = f"isf {release}"
html_static_path: list[str] = []


# ----------------------------------------------------------------------------------------------
# The `isf-cli` directive: a CLI reference generated from the argparse parser.
# ----------------------------------------------------------------------------------------------
_log = sphinx_logging.getLogger(__name__)
_USAGE_WIDTH = 88


def _cli_parser() -> argparse.ArgumentParser:
    from isf.cli import _parser

    return _parser()


def _subcommands(parser: argparse.ArgumentParser) -> tuple[dict, dict]:
    """Map subcommand name -> its parser, and name -> its one-line help."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            return dict(action.choices), helps
    return {}, {}


def _invocation(action: argparse.Action) -> str:
    """``--top K, -k K`` style text of one argument."""
    if not action.option_strings:
        return action.metavar or action.dest
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    if action.metavar is not None:
        metavar = action.metavar
    elif action.choices is not None:
        metavar = "{" + ",".join(map(str, action.choices)) + "}"
    else:
        metavar = action.dest.upper()
    return ", ".join(f"{opt} {metavar}" for opt in action.option_strings)


def _argument_list(parser: argparse.ArgumentParser) -> nodes.definition_list:
    items = nodes.definition_list()
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        text = action.help or ""
        notes = []
        if action.required and action.option_strings:
            notes.append("required")
        if isinstance(action, argparse._AppendAction) and "repeatable" not in text:
            notes.append("repeatable")
        if notes:
            text = f"{text} ({'; '.join(notes)})" if text else "; ".join(notes)
        term = nodes.term("", "")
        term += nodes.literal(text=_invocation(action))
        body = nodes.definition("", nodes.paragraph(text=text))
        items += nodes.definition_list_item("", term, body)
    return items


class IsfCliDirective(SphinxDirective):
    """Render ``isf`` (no argument) or one subcommand (``plan``, ``tag``, ...).

    Output: the usage line, the description, and every argument with its help. Every
    subcommand of the parser must be rendered somewhere, or the build warns (so a new
    subcommand cannot go undocumented).
    """

    optional_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        parser = _cli_parser()
        subs, helps = _subcommands(parser)
        name = self.arguments[0] if self.arguments else None
        self.env.note_dependency(str(Path(isf.__file__).with_name("cli.py")))  # rebuild on edits
        if name is not None:
            if name not in subs:
                raise self.error(f"isf has no subcommand {name!r}; known: {', '.join(subs)}")
            _cli_documented(self.env).add(name)
            target, description = subs[name], subs[name].description or helps[name]
        else:
            target, description = parser, parser.description
        target.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=_USAGE_WIDTH)
        out: list[nodes.Node] = []
        usage = target.format_usage().strip()
        out.append(nodes.literal_block(usage, usage, language="text"))
        if description:
            out.append(nodes.paragraph(text=description))
        out.append(_argument_list(target))
        if name is None and subs:
            table = nodes.definition_list()
            for sub_name in subs:
                term = nodes.term("", "")
                term += nodes.literal(text=f"isf {sub_name}")
                table += nodes.definition_list_item(
                    "", term, nodes.definition("", nodes.paragraph(text=helps[sub_name]))
                )
            out.append(nodes.paragraph(text="Commands:"))
            out.append(table)
        box = nodes.container("", *out, classes=["isf-cli"])
        box["support_smartquotes"] = False  # keep `--contact` and 'quotes' exactly as typed
        return [box]


def _cli_documented(env) -> set[str]:
    if not hasattr(env, "isf_cli_documented"):
        env.isf_cli_documented = {}
    docname = env.docname
    return env.isf_cli_documented.setdefault(docname, set())


def _purge_cli(app, env, docname) -> None:
    getattr(env, "isf_cli_documented", {}).pop(docname, None)


def _merge_cli(app, env, docnames, other) -> None:
    env.isf_cli_documented = getattr(env, "isf_cli_documented", {})
    env.isf_cli_documented.update(getattr(other, "isf_cli_documented", {}))


def _check_cli_complete(app, env) -> None:
    documented = set().union(*getattr(env, "isf_cli_documented", {}).values())
    subs, _ = _subcommands(_cli_parser())
    missing = sorted(set(subs) - documented)
    if missing:
        _log.warning("CLI reference: subcommand(s) %s have no `isf-cli` directive; add them to "
                     "docs/cli.md", ", ".join(missing), type="isf", subtype="cli")


# ----------------------------------------------------------------------------------------------
# Re-exported names. `isf.gripper.model.Gripper` (how an annotation spells a type), `isf.Gripper` (how
# the API page documents it) and a short `Gripper` in a docstring of `isf.planning.planner` all name the
# same Python object. When Sphinx cannot resolve such a reference, import it (relative to the
# module of the page's context and to the module that defines the docstring) and, if that is an
# object the API page documents, link to the documented name. A name that does not import, or
# imports to something undocumented, stays broken and fails the strict build.
# ----------------------------------------------------------------------------------------------
_DOCSTRING_OF = re.compile(r"docstring of (isf[\w.]*)")


def _import_dotted(name: str):
    """The object a dotted ``isf...`` name denotes (attributes win over submodules), or None."""
    parts = name.split(".")
    try:
        obj = importlib.import_module(parts[0])
    except ImportError:
        return None
    for i, part in enumerate(parts[1:], start=1):
        if hasattr(obj, part):
            obj = getattr(obj, part)
            continue
        try:
            obj = importlib.import_module(".".join(parts[: i + 1]))
        except ImportError:
            return None
    return obj


_ALIASES: dict[int, dict[int, str]] = {}  # per process only: ids mean nothing after pickling


def _documented_by_object(env) -> dict[int, str]:
    """id(object) -> its documented name, for every ``isf`` object on the API page."""
    domain = env.get_domain("py")
    key = len(domain.objects)
    if key not in _ALIASES:
        table = {}
        for fullname, entry in domain.objects.items():
            if entry.aliased or not fullname.startswith("isf"):
                continue
            obj = _import_dotted(fullname)
            if obj is not None and not isinstance(obj, (int, float, str, bool, bytes, type(None))):
                table.setdefault(id(obj), fullname)
        _ALIASES.clear()
        _ALIASES[key] = table
    return _ALIASES[key]


def _candidates(node) -> list[str]:
    target = node.get("reftarget", "")
    if target.startswith("isf."):
        return [target]
    scopes = []
    module, cls = node.get("py:module"), node.get("py:class")
    if module:
        if cls:
            scopes.append(f"{module}.{cls}")
        scopes.append(module)
    match = _DOCSTRING_OF.search(str(node.source or ""))
    if match:  # the docstring's own module (and class), where its author wrote short names
        owner = _import_dotted(match.group(1))
        home = getattr(owner, "__module__", None) or getattr(owner, "__name__", None)
        qualname = getattr(owner, "__qualname__", "")
        if home and "." in qualname:
            scopes.append(f"{home}.{qualname.rsplit('.', 1)[0]}")
        if home:
            scopes.append(home)
    return [f"{scope}.{target}" for scope in scopes if scope.startswith("isf")]


def _resolve_reexport(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    documented = _documented_by_object(env)
    domain = env.get_domain("py")
    for candidate in _candidates(node):
        obj = _import_dotted(candidate)
        name = documented.get(id(obj)) if obj is not None else None
        if obj is None:  # an instance attribute: documented under its class, not importable
            owner, _, attr = candidate.rpartition(".")
            owner_obj = _import_dotted(owner)
            owner_name = documented.get(id(owner_obj)) if owner_obj is not None else None
            if owner_name and f"{owner_name}.{attr}" in domain.objects:
                name = f"{owner_name}.{attr}"
        if name is not None and name != node.get("reftarget"):
            return domain.resolve_xref(
                env, node["refdoc"], app.builder, node["reftype"], name, node, contnode
            )
    return None


# ----------------------------------------------------------------------------------------------
# Small autodoc adjustments.
# ----------------------------------------------------------------------------------------------
def _skip_namedtuple_fields(app, what, name, obj, skip, options):
    """NamedTuple fields are documented by the class's ``Attributes:`` section already; their
    generated "Alias for field number N" properties would be duplicate descriptions."""
    if (getattr(obj, "__doc__", None) or "").startswith("Alias for field number"):
        return True
    return None


def _post_init_attributes(app, what, name, obj, options, lines) -> None:
    """Document ``self.x = ...`` + docstring assignments of a dataclass's ``__post_init__``.

    Sphinx only reads such attribute docstrings from ``__init__``; dataclasses compute their
    derived attributes in ``__post_init__`` (e.g. ``Gripper.contact_links``).
    """
    if what != "class" or not dataclasses.is_dataclass(obj) or "__post_init__" not in vars(obj):
        return
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(obj.__post_init__)))
    except (OSError, TypeError, SyntaxError):
        return
    body = tree.body[0].body if tree.body else []
    for stmt, following in zip(body, body[1:]):
        target = stmt.target if isinstance(stmt, ast.AnnAssign) else (
            stmt.targets[0] if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 else None)
        doc = following.value.value if (
            isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant)
            and isinstance(following.value.value, str)) else None
        if not (isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name)
                and target.value.id == "self" and doc and not target.attr.startswith("_")):
            continue
        lines.extend(["", f".. attribute:: {target.attr}"])
        if isinstance(stmt, ast.AnnAssign):
            lines.append(f"   :type: {ast.unparse(stmt.annotation)}")
        lines.append("")
        lines.extend("   " + line for line in inspect.cleandoc(doc).splitlines())


def setup(app):
    app.add_directive("isf-cli", IsfCliDirective)
    app.connect("env-purge-doc", _purge_cli)
    app.connect("env-merge-info", _merge_cli)
    app.connect("env-check-consistency", _check_cli_complete)
    app.connect("missing-reference", _resolve_reexport)
    app.connect("autodoc-skip-member", _skip_namedtuple_fields)
    app.connect("autodoc-process-docstring", _post_init_attributes)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
