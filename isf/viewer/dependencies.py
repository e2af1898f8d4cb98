"""The packages of ``isf show`` and ``isf export`` (plotly and yourdfpy, dependencies of isf that
an environment may still lack: a one-line error instead of a traceback)."""

from __future__ import annotations

import importlib

from ..exceptions import InvalidInputError

__all__ = ["VIEWER_PACKAGES", "require_viewer"]

VIEWER_PACKAGES = {"yourdfpy": "yourdfpy", "plotly": "plotly"}
"""Modules the viewer needs, with the package that installs each (``isf export`` needs only
yourdfpy)."""


def require_viewer(command: str, modules: tuple[str, ...] = tuple(VIEWER_PACKAGES)) -> None:
    """Import ``modules`` (of ``VIEWER_PACKAGES``), or raise one line that
    names the fix.

    Raises:
        InvalidInputError: one of them is not installed.
    """
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            raise InvalidInputError(f"isf {command} needs {VIEWER_PACKAGES[module]}, which is not "
                                    "installed: pip install plotly yourdfpy (dependencies of isf)") from None
