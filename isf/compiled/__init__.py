"""The numba machinery of isf: how kernels are compiled, cached and warmed up.

- :mod:`isf.compiled.leaf`: the decorator of per-query kernels compiled without reference
  counting and inlined into their callers.
- :mod:`isf.compiled.cache`: numba's disk cache kept consistent with the sources (run when
  isf is imported).
- :mod:`isf.compiled.warming`: :func:`~isf.compiled.warming.warm_up` compiles, or loads, every
  kernel before anything is timed.

This package imports nothing of isf's own, so that every layer can use its decorators.
"""
