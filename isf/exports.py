"""Public names of a package that load on first use (:pep:`562`).

A package lists each public name with the module that defines it; the module is imported the
first time the name is read (then the name is an ordinary attribute). ``import isf`` and the
commands that need no kernels therefore load none of numba, Pinocchio, trimesh or scipy.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, sources: Mapping[str, str]) -> tuple[Callable, Callable]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` whose public names are
    the keys of ``sources``, each defined in the module ``package + "." + sources[name]``."""

    def __getattr__(name: str):
        source = sources.get(name)
        if source is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{source}"), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *sources})

    return __getattr__, __dir__
