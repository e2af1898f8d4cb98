"""Array copies inside compiled kernels: :func:`copy_into`.

numba compiles a slice assignment from an array (``dst[a:b] = src``, ``T[i] = Tc[j]``) with a
shape check whose error message spells both shapes out as text, and compiling that text
formatting (numba's string functions) costs seconds: about 2 s the first time in a process, and
more in every kernel that links it, a tenth of the ISF engine's compile time
(docs/design-decisions.md, "Compiled kernels: the cache and the first run"). isf's kernels therefore copy arrays with
:func:`copy_into`, or with a loop where the destination is a fancy index (``dst[rows] = src``
writes through ``rows``; ``dst[rows]`` would be a copy) or not contiguous. The values copied,
and so every result, are the same.
"""

from __future__ import annotations

from .leaf import leaf

__all__ = ["copy_into"]


@leaf
def copy_into(dst, src):
    """Copy ``src`` into ``dst``, ``dst[...] = src`` without broadcasting: arrays of one shape,
    each contiguous in memory (numba refuses to compile the call for others); raises
    ``ValueError`` when the shapes differ."""
    if dst.shape != src.shape:
        raise ValueError("copy_into: the arrays differ in shape")
    flat_dst, flat_src = dst.reshape(dst.size), src.reshape(src.size)
    for i in range(flat_src.size):
        flat_dst[i] = flat_src[i]
