"""Exact nearest-neighbour queries on a fixed point set: a compiled k-d tree.

ISF asks one question of the object again and again (the nearest surface point of each
contact point, about a million times per plan), on a point set that never changes.
:class:`NearestPoints` answers it with a k-d tree built once and searched in compiled
code (one call per batch of queries, no Python per query). A search can start from a
guess (the point found for the same query in the previous ISF iteration): its distance
bounds the search from the start, so the tree prunes most branches at once. The answer
is exact either way: the nearest distance, and one point at that distance.
:meth:`NearestPoints.query_k` answers the k nearest points the same way (the collision
checks and the collision repair ask for the tangent planes of the 6 nearest).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["NearestPoints"]

LEAF_SIZE = 8
"""Points per leaf at most."""


@njit(cache=True)
def _build(points, leaf_size):
    """The tree of ``points`` (N, 3): ``order`` (N,) (the points of a node are
    ``order[start:stop]``) and per node ``start``, ``stop``, ``axis`` (-1 for a leaf), ``split``,
    ``left``, ``right`` (-1 for a leaf). Nodes are numbered breadth first.

    A node of more than ``leaf_size`` points is sorted (stably) along its widest extent and
    split at its median; a node whose points all coincide stays a leaf.
    """
    n = len(points)
    cap = 2 * n + 1  # a split leaves no child empty, so at most n leaves
    order = np.arange(n)
    start, stop = np.empty(cap, np.int64), np.empty(cap, np.int64)
    axis, split, left = np.full(cap, -1, np.int64), np.zeros(cap), np.full(cap, -1, np.int64)
    start[0], stop[0] = 0, n
    key, moved = np.empty(n), np.empty(n, np.int64)
    lo, hi = np.empty(3), np.empty(3)
    n_nodes, node = 1, 0
    while node < n_nodes:  # children are numbered in the order of their parents
        a, b = start[node], stop[node]
        node += 1
        if b - a <= leaf_size:
            continue
        lo[:] = points[order[a]]
        hi[:] = lo
        for i in range(a + 1, b):
            for d in range(3):
                lo[d] = min(lo[d], points[order[i], d])
                hi[d] = max(hi[d], points[order[i], d])
        widest = 0
        for d in (1, 2):
            if hi[d] - lo[d] > hi[widest] - lo[widest]:
                widest = d
        if hi[widest] - lo[widest] <= 0.0:
            continue
        for i in range(a, b):
            key[i - a] = points[order[i], widest]
        rank = np.argsort(key[: b - a], kind="mergesort")  # stable: ties keep their order
        for i in range(b - a):
            moved[i] = order[a + rank[i]]
        order[a:b] = moved[: b - a]
        middle = (a + b) // 2
        parent = node - 1
        axis[parent], split[parent], left[parent] = widest, points[order[middle], widest], n_nodes
        start[n_nodes], stop[n_nodes] = a, middle
        start[n_nodes + 1], stop[n_nodes + 1] = middle, b
        n_nodes += 2
    left = left[:n_nodes].copy()
    right = np.where(left >= 0, left + 1, -1)
    return (order, start[:n_nodes].copy(), stop[:n_nodes].copy(), axis[:n_nodes].copy(),
            split[:n_nodes].copy(), left, right)


_PRUNE_SLACK = 1.0 + 1e-12
"""A cell is skipped only when its bound exceeds the best (k-th) squared distance by this
factor, so that the rounding of the incremental bound can never hide a tied point."""


@njit(cache=True, error_model="numpy")
def _descend(node, bound, ox, oy, oz, x, y, z, limit, axis, split, left, right,
             stack_node, stack_bound, stack_offset, top):
    """From ``node`` (squared cell distance ``bound``, query offsets ``ox, oy, oz`` from its cell)
    down to the leaf holding the query ``(x, y, z)``, pushing every far side whose cell may hold
    a point within ``limit`` (a squared distance) with its incremental bound (Arya and Mount).
    Returns the leaf and the new stack top."""
    while axis[node] >= 0:
        d = axis[node]
        gap = (x if d == 0 else (y if d == 1 else z)) - split[node]
        near, far = (left[node], right[node]) if gap < 0.0 else (right[node], left[node])
        old = ox if d == 0 else (oy if d == 1 else oz)
        far_bound = bound - old * old + gap * gap
        if far_bound <= limit:
            top += 1
            stack_node[top], stack_bound[top] = far, far_bound
            stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2] = ox, oy, oz
            stack_offset[top, d] = gap
        node = near
    return node, top


@njit(cache=True, error_model="numpy")
def _query(original, points, order, start, stop, axis, split, left, right, queries, guess):
    """Nearest point of each query (M, 3): distances (M,) and indices (M,) into ``original``
    (N, 3). ``points`` are the same points in tree order (``points[i]`` is
    ``original[order[i]]``, so a leaf is contiguous). ``guess`` (M,): a candidate index per
    query to bound the search with, or -1."""
    m = len(queries)
    distance, index = np.empty(m), np.empty(m, np.int64)
    stack_node = np.empty(128, np.int64)
    stack_bound = np.empty(128)
    stack_offset = np.empty((128, 3))
    for k in range(m):
        x, y, z = queries[k, 0], queries[k, 1], queries[k, 2]
        best, best_d2 = -1, np.inf
        if guess[k] >= 0:
            g = guess[k]
            best = g
            best_d2 = (original[g, 0] - x) ** 2 + (original[g, 1] - y) ** 2 + (original[g, 2] - z) ** 2
        # a stacked node carries its cell's squared distance and the query's offsets from it
        top = 0
        stack_node[0], stack_bound[0] = 0, 0.0
        stack_offset[0, :] = 0.0
        while top >= 0:
            node, bound = stack_node[top], stack_bound[top]
            ox, oy, oz = stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2]
            top -= 1
            if bound > best_d2 * _PRUNE_SLACK:
                continue
            node, top = _descend(node, bound, ox, oy, oz, x, y, z, best_d2 * _PRUNE_SLACK, axis, split,
                                 left, right, stack_node, stack_bound, stack_offset, top)
            for i in range(start[node], stop[node]):
                d2 = (points[i, 0] - x) ** 2 + (points[i, 1] - y) ** 2 + (points[i, 2] - z) ** 2
                if d2 <= best_d2:
                    p = order[i]
                    if d2 < best_d2 or p < best:
                        best, best_d2 = p, d2
        distance[k], index[k] = np.sqrt(best_d2), best
    return distance, index


@njit(cache=True, error_model="numpy")
def _query_k(points, order, start, stop, axis, split, left, right, queries, k):
    """The ``k`` nearest points of each query (M, 3): distances (M, k) and indices (M, k) into
    the original points, nearest first, ties by lower index; missing neighbours (k > N) are
    ``inf`` and N. ``points`` are in tree order (see :func:`_query`). Each query keeps its best
    ``k`` in a sorted insertion list; the worst of them bounds the search."""
    m, n = len(queries), len(points)
    distance, index = np.empty((m, k)), np.empty((m, k), np.int64)
    stack_node = np.empty(128, np.int64)
    stack_bound = np.empty(128)
    stack_offset = np.empty((128, 3))
    best_d2, best = np.empty(k), np.empty(k, np.int64)
    last = k - 1
    for q in range(m):
        x, y, z = queries[q, 0], queries[q, 1], queries[q, 2]
        best_d2[:] = np.inf
        best[:] = n
        worst_d2, worst = np.inf, n
        top = 0
        stack_node[0], stack_bound[0] = 0, 0.0
        stack_offset[0, :] = 0.0
        while top >= 0:
            node, bound = stack_node[top], stack_bound[top]
            ox, oy, oz = stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2]
            top -= 1
            if bound > worst_d2 * _PRUNE_SLACK:
                continue
            node, top = _descend(node, bound, ox, oy, oz, x, y, z, worst_d2 * _PRUNE_SLACK, axis, split,
                                 left, right, stack_node, stack_bound, stack_offset, top)
            for i in range(start[node], stop[node]):
                d2 = (points[i, 0] - x) ** 2 + (points[i, 1] - y) ** 2 + (points[i, 2] - z) ** 2
                if d2 > worst_d2:
                    continue
                p = order[i]
                if d2 == worst_d2 and p > worst:
                    continue
                j = last  # insert (d2, p) in order, dropping the worst
                while j > 0 and (best_d2[j - 1] > d2 or (best_d2[j - 1] == d2 and best[j - 1] > p)):
                    best_d2[j], best[j] = best_d2[j - 1], best[j - 1]
                    j -= 1
                best_d2[j], best[j] = d2, p
                worst_d2, worst = best_d2[last], best[last]
        for j in range(k):
            distance[q, j], index[q, j] = np.sqrt(best_d2[j]), best[j]
    return distance, index


class NearestPoints:
    """Exact nearest-neighbour search on a fixed point set.

    Args:
        points: the points, (N, 3), N >= 1.
    """

    def __init__(self, points: np.ndarray):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 3 or not len(self.points):
            raise ValueError(f"need points of shape (N, 3) with N >= 1, got {self.points.shape}")
        self._tree = _build(self.points, LEAF_SIZE)
        self._tree_points = self.points[self._tree[0]]  # leaves contiguous

    def query(self, queries: np.ndarray, guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Nearest point of each query point.

        Args:
            queries: query points, (M, 3).
            guess: optional candidate index per query (M,) (-1 for none), e.g. the answer of a
                previous query from nearby; it speeds the search and never changes its answer.

        Returns:
            distances (M,) and indices (M,) into ``points``; among equally near points the
            lowest index.
        """
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        if guess is None:
            guess = np.full(len(queries), -1, dtype=np.int64)
        else:
            guess = np.ascontiguousarray(guess, dtype=np.int64).reshape(-1)
            if len(guess) != len(queries) or (len(guess) and not (
                    -1 <= guess.min() and guess.max() < len(self.points))):
                raise ValueError(f"guess must hold one index in [-1, {len(self.points) - 1}] per "
                                 f"query ({len(queries)}); pass None for no guesses")
        return _query(self.points, self._tree_points, *self._tree, queries, guess)


    def query_k(self, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points of each query point.

        Args:
            queries: query points, (M, 3).
            k: neighbours per query, >= 1. When ``k`` exceeds the number of points N, the
                missing neighbours come last with distance ``inf`` and index N (as scipy's
                cKDTree reports them).

        Returns:
            distances (M, k) and indices (M, k) into ``points`` (2-D also for k = 1), nearest
            first; among equally near points the lower index first (so the set is the k least
            by distance, then index).
        """
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise ValueError(f"k must be a positive integer, got {k!r}; ask for at least one neighbour")
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        return _query_k(self._tree_points, *self._tree, queries, int(k))
