"""The numba machinery of isf: how kernels are compiled and how their disk cache stays valid.

- :mod:`isf.compiled.kernels`: :func:`~isf.compiled.kernels.kernel`, the decorator of every
  compiled function (cached, releasing the GIL, numpy's error model).
- :mod:`isf.compiled.leaf`: :func:`~isf.compiled.leaf.leaf`, the decorator of per-query
  kernels compiled without reference counting and inlined into their callers.
- :mod:`isf.compiled.arrays`: :func:`~isf.compiled.arrays.copy_into`, the kernels' array copy
  (numba's slice assignment from an array compiles seconds more).
- ``isf.compiled.flags``: numba's compiler flags hashed and compared without rebuilding every
  option (a few seconds of every compile; installed before the first kernel is made).
- :mod:`isf.compiled.cache`: numba's disk cache kept consistent with the sources (run before
  the first kernel is defined).
- ``isf.compiled.healing``: ``cached_njit``, numba's cache of one
  function dropping entries it cannot load (both decorators compile through it).
- ``isf.compiled.lock``: one process at a time compiles into a cache.
- ``isf.compiled.workers``: compiling in helper processes that die with their parent.

This package imports nothing of isf's own, so that every layer can use its decorators.
Compiling every kernel ahead of time (:func:`isf.warming.warm_up`) needs the whole library and
so lives at the top level.
"""
