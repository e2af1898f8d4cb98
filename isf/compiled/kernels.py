"""The decorator of isf's compiled kernels: :func:`kernel`.

Every compiled function of isf is a numba ``njit`` function with the same options: cached on
disk (:mod:`isf.compiled.cache` keeps that cache consistent with the sources,
``isf.compiled.healing`` drops entries that cannot be loaded), releasing the
GIL (the planner's worker threads run kernels side by side) and numpy's error model (a division
by zero gives ``inf`` or ``nan`` as in numpy, without a check per division). Small helpers are
inlined into their callers by numba (``inline=True``). Per-query kernels that must run without
reference counting use :func:`isf.compiled.leaf.leaf` instead.
"""

from __future__ import annotations

from .healing import cached_njit

__all__ = ["kernel"]


def kernel(function=None, *, inline: bool = False, error_model: str = "numpy"):
    """Compile ``function`` as an isf kernel (see the module docstring).

    Use as ``@kernel``, ``@kernel(inline=True)`` (numba inlines it into each caller) or
    ``@kernel(error_model="python")`` (divisions by zero raise, for kernels whose callers rely
    on it).
    """
    options = dict(nogil=True)
    if error_model != "python":
        options["error_model"] = error_model
    if inline:
        options["inline"] = "always"

    def compile_(python_function):
        return cached_njit(python_function, **options)

    return compile_ if function is None else compile_(function)
