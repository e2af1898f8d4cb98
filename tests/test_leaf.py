"""Leaf kernels (isf.compiled.leaf): compiled without reference counting where numba allows it, with the
answers of the same function compiled as an ordinary kernel."""

import numpy as np
from numba import njit
from numba.core.options import DefaultOptions

from isf.compiled import leaf as leaf_module
from isf.compiled.leaf import leaf
from isf.fitting import _box_qp as box_qp
from isf.fitting import moment_kernels
from isf.search.nearest import NearestPoints, nearest_point, tree_nearest

LEAVES = (nearest_point, tree_nearest, moment_kernels.solve_small, moment_kernels._group_pose,
          moment_kernels._residual, moment_kernels._add_palm_sandwich, moment_kernels._add_sandwich,
          box_qp._primal_dual, box_qp._primal)
"""Kernels measured to need it (``docs/benchmarks.md``, section "bench_rounds")."""


def _first_closer(x, points, limit):
    """A leaf-shaped function: reads a tuple of arrays, branches, allocates nothing."""
    values, weights = points
    best = -1
    for i in range(len(values)):
        if abs(values[i] - x) * weights[i] < limit:
            best = i
            break
    return best


def test_the_hot_helpers_are_leaves_where_numba_allows():
    assert set(leaf_module._OPTIONS) == {"_nrt", "forceinline"} & set(dir(DefaultOptions))
    expected = leaf_module._OPTIONS
    for kernel in LEAVES:
        options = kernel.targetoptions
        assert {name: options.get(name) for name in expected} == expected


def test_a_leaf_answers_as_an_ordinary_kernel(monkeypatch):
    values, weights = np.array([0.5, 0.1, 0.3]), np.array([1.0, 2.0, 1.0])
    plain = njit(_first_closer)
    as_leaf = leaf(_first_closer)
    monkeypatch.setattr(leaf_module, "_OPTIONS", {})  # a numba without the options
    fallback = leaf(_first_closer)
    assert "_nrt" not in fallback.targetoptions  # an ordinary kernel
    for x, limit in ((0.3, 0.05), (0.1, 0.1), (0.9, 0.01)):
        want = plain(x, (values, weights), limit)
        assert as_leaf(x, (values, weights), limit) == want
        assert fallback(x, (values, weights), limit) == want


def test_leaf_searches_in_a_compiled_loop_match_brute_force():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(400, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)  # a sphere's surface sample
    search = NearestPoints(points, graph=True)
    queries = points[rng.integers(0, 400, 300)] * 1.05 + rng.normal(scale=0.02, size=(300, 3))
    guesses = rng.integers(-1, 400, 300)
    _, found = search.query(queries, guesses)  # nearest_point per query in a compiled loop
    distances = np.linalg.norm(queries[:, None] - points[None], axis=2)
    np.testing.assert_array_equal(found, distances.argmin(axis=1))
