"""Compiling isf's per-query kernels: :func:`leaf`.

A *leaf* is a small compiled function that a compiled loop calls once per query or per item (a
nearest point, one link's sums in IPFO): it reads arrays and writes into scratch arrays it is
given, and allocates none. Compiled as an ordinary numba function, or inlined into its loop by
numba (``inline="always"``), it takes and drops a reference to every array it receives on every
call, unless numba can prove the pair removable, which it could not for leaves that take a
tuple of arrays and branch (the searches take the k-d tree's arrays as one NamedTuple), or that are called
with views of larger arrays (IPFO's per-link helpers). Those reference counts are atomic
operations that cost more than the leaf's own work (the measured figures, leaf against ordinary
kernel, are in ``docs/benchmarks.md``, section "bench_rounds"). A leaf is therefore compiled
without numba's reference counting (``_nrt=False``: it must not allocate, or keep an array
beyond the call) and inlined by LLVM into each caller (``forceinline=True``), which keeps the
answers and the arithmetic, and so every result, bit for bit.

Where the installed numba does not know these options, a leaf is an ordinary cached kernel:
slower, with the same results.
"""

from __future__ import annotations

from numba.core.options import DefaultOptions

from .healing import cached_njit

__all__ = ["leaf"]

_OPTIONS = {name: value for name, value in (("_nrt", False), ("forceinline", True))
            if hasattr(DefaultOptions, name)}


def leaf(function):
    """Compile ``function`` as a leaf kernel (see the module docstring): cached, releasing the
    GIL, numpy's error model (as isf's other kernels), no reference counting, inlined by
    LLVM into its callers."""
    return cached_njit(function, nogil=True, error_model="numpy", **_OPTIONS)
