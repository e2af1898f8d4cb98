"""Exact nearest-neighbour queries on a fixed point set: a compiled k-d tree.

ISF asks one question of the object again and again (the nearest surface point of each
contact point, about a million times per plan), on a point set that never changes.
:class:`NearestPoints` answers it with a k-d tree built once and searched in compiled
code (one call per batch of queries, no Python per query). A search can start from a
guess (the point found for the same query in the previous ISF iteration): its distance
bounds the search from the start, so the tree prunes most branches at once. The answer
is exact either way: the nearest distance, and one point at that distance.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["NearestPoints"]

LEAF_SIZE = 8
"""Points per leaf at most."""


def _build(points: np.ndarray, leaf_size: int):
    """The tree of ``points`` (N, 3), built a level at a time (every node of a level is split
    with one sort): ``order`` (N,) (the points of a node are ``order[start:stop]``) and per
    node ``start``, ``stop``, ``axis`` (-1 for a leaf), ``split``, ``left``, ``right``.

    A node of more than ``leaf_size`` points is split at the median of its widest extent; a
    node whose points all coincide stays a leaf.
    """
    n = len(points)
    order = np.arange(n)
    start, stop = [np.array([0])], [np.array([n])]
    axis, split, left = [np.array([-1])], [np.array([0.0])], [np.array([-1])]
    a, b, ids = start[0], stop[0], np.array([0])  # the nodes of the level, in order of their ranges
    n_nodes = 1
    while len(ids):
        big = b - a > leaf_size
        a, b, ids = a[big], b[big], ids[big]
        if not len(ids):
            break
        sizes = b - a
        first = np.cumsum(sizes) - sizes
        node = np.repeat(np.arange(len(ids)), sizes)  # the node of each position below
        position = np.arange(len(node)) - first[node] + a[node]
        coords = points[order[position]]
        extent = np.maximum.reduceat(coords, first) - np.minimum.reduceat(coords, first)
        widest = extent.argmax(axis=1)
        key = coords[np.arange(len(node)), widest[node]]
        order[position] = order[position[np.lexsort((key, node))]]  # stable: ties keep their order
        keep = extent.max(axis=1) > 0.0
        a, b, ids, widest = a[keep], b[keep], ids[keep], widest[keep]
        middle = (a + b) // 2
        k = len(ids)
        children = n_nodes + np.arange(2 * k)
        for values, where, what in ((axis, ids, widest), (split, ids, points[order[middle], widest]),
                                    (left, ids, children[0::2])):
            values.append((where, what))
        a, b = np.stack([a, middle], axis=1).ravel(), np.stack([middle, b], axis=1).ravel()
        start.append(a)
        stop.append(b)
        axis.append(np.full(2 * k, -1))
        split.append(np.zeros(2 * k))
        left.append(np.full(2 * k, -1))
        ids, n_nodes = children, n_nodes + 2 * k

    def assemble(parts, dtype):
        values = np.concatenate([p for p in parts if isinstance(p, np.ndarray)]).astype(dtype)
        for p in parts:
            if isinstance(p, tuple):
                values[p[0]] = p[1]
        return values

    left_ = assemble(left, np.int64)
    right_ = np.where(left_ >= 0, left_ + 1, -1)
    return (order, np.concatenate(start).astype(np.int64), np.concatenate(stop).astype(np.int64),
            assemble(axis, np.int64), assemble(split, float), left_, right_)


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
        # Each stacked node carries its cell's squared distance from the query and the
        # query's offset from the cell along each axis (Arya and Mount's incremental distance).
        top = 0
        stack_node[0], stack_bound[0] = 0, 0.0
        stack_offset[0, :] = 0.0
        while top >= 0:
            node, bound = stack_node[top], stack_bound[top]
            ox, oy, oz = stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2]
            top -= 1
            if bound > best_d2:
                continue
            while axis[node] >= 0:  # descend towards the query, deferring the far sides
                d = axis[node]
                gap = (x if d == 0 else (y if d == 1 else z)) - split[node]
                near, far = (left[node], right[node]) if gap < 0.0 else (right[node], left[node])
                old = ox if d == 0 else (oy if d == 1 else oz)
                far_bound = bound - old * old + gap * gap
                if far_bound <= best_d2:
                    top += 1
                    stack_node[top], stack_bound[top] = far, far_bound
                    stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2] = ox, oy, oz
                    stack_offset[top, d] = gap
                node = near
            for i in range(start[node], stop[node]):
                d2 = (points[i, 0] - x) ** 2 + (points[i, 1] - y) ** 2 + (points[i, 2] - z) ** 2
                if d2 <= best_d2:
                    p = order[i]
                    if d2 < best_d2 or p < best:
                        best, best_d2 = p, d2
        distance[k], index[k] = np.sqrt(best_d2), best
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
                previous query from nearby; it speeds the search and never changes its answer's
                distance.

        Returns:
            distances (M,) and indices (M,) into ``points``; among equally near points the
            lowest index.
        """
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        if guess is None:
            guess = np.full(len(queries), -1, dtype=np.int64)
        else:
            guess = np.ascontiguousarray(guess, dtype=np.int64)
        return _query(self.points, self._tree_points, *self._tree, queries, guess)
