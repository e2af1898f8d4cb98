"""A compiled k-d tree on a fixed point set: exact nearest and k-nearest points, one query at a time.

The search behind :class:`isf.search.nearest.NearestPoints`. Its searches are numba functions on
the tree's arrays, called per query from compiled loops: squared distances
``(px - x)**2 + (py - y)**2 + (pz - z)**2`` in that order (the distances scipy's cKDTree
reports), and among equally near points the lowest index. A search may start from a best
candidate found elsewhere (a guess): its distance bounds the search from the start.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel

__all__ = ["LEAF_SIZE", "PRUNE_SLACK", "STACK_SIZE", "KDTree", "SearchScratch", "build", "k_nearest",
           "nearest", "squared_distance"]

LEAF_SIZE = 8
"""Points per leaf at most."""

PRUNE_SLACK = 1.0 + 1e-12
"""A cell is skipped only when its bound exceeds the best (k-th) squared distance by this
factor, so that the rounding of the incremental bound can never hide a tied point."""

STACK_SIZE = 128
"""Depth of a search's stack of pending cells (a tree of 2**64 points needs less)."""


class KDTree(NamedTuple):
    """The arrays of a k-d tree (:func:`build`); nodes are numbered breadth first, N points."""

    points: np.ndarray
    """The points in tree order, (N, 3) float64, m: ``points[i]`` is point ``order[i]``."""
    order: np.ndarray
    """The point index of each tree position, (N,) int64; a node's points are
    ``order[start:stop]``."""
    start: np.ndarray
    """First tree position of each node, (nodes,) int64."""
    stop: np.ndarray
    """One past the last tree position of each node, (nodes,) int64."""
    axis: np.ndarray
    """Split axis of each node (0, 1, 2; -1 for a leaf), (nodes,) int64."""
    split: np.ndarray
    """Split coordinate of each node, (nodes,) float64, m."""
    left: np.ndarray
    """Child below the split, (nodes,) int64 (-1 for a leaf)."""
    right: np.ndarray
    """Child above the split, (nodes,) int64 (-1 for a leaf)."""


class SearchScratch(NamedTuple):
    """Scratch of one search (:func:`nearest`, :func:`k_nearest`): a stack of pending cells,
    :data:`STACK_SIZE` rows."""

    node: np.ndarray
    """The cells' nodes, (STACK_SIZE,) int64."""
    bound: np.ndarray
    """Their squared distances from the query, (STACK_SIZE,) float64, m^2."""
    offset: np.ndarray
    """The query's offsets from each cell along the three axes, (STACK_SIZE, 3) float64, m."""


@kernel(error_model="python")
def build(points, leaf_size):
    """The :class:`KDTree` of ``points`` (N, 3).

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
        for d in range(3):
            lo[d] = hi[d] = points[order[a], d]
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
        for i in range(b - a):
            order[a + i] = moved[i]
        middle = (a + b) // 2
        parent = node - 1
        axis[parent], split[parent], left[parent] = widest, points[order[middle], widest], n_nodes
        start[n_nodes], stop[n_nodes] = a, middle
        start[n_nodes + 1], stop[n_nodes + 1] = middle, b
        n_nodes += 2
    left = left[:n_nodes].copy()
    right = np.full(n_nodes, -1, np.int64)  # a leaf's children: none
    for i in range(n_nodes):
        if left[i] >= 0:
            right[i] = left[i] + 1
    return KDTree(points[order], order, start[:n_nodes].copy(), stop[:n_nodes].copy(),
                  axis[:n_nodes].copy(), split[:n_nodes].copy(), left, right)


@kernel
def _descend(node, bound, ox, oy, oz, x, y, z, limit, tree, stack, top):
    """From ``node`` (squared cell distance ``bound``, query offsets ``ox, oy, oz`` from its cell)
    down to the leaf holding the query ``(x, y, z)``, pushing every far side whose cell may hold
    a point within ``limit`` (a squared distance) with its incremental bound (Arya and Mount).
    Returns the leaf and the new stack top (``stack``: :class:`SearchScratch`)."""
    axis, split, left, right = tree.axis, tree.split, tree.left, tree.right
    stack_node, stack_bound, stack_offset = stack.node, stack.bound, stack.offset
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


@kernel(inline=True)
def squared_distance(points, i, x, y, z):
    """``|points[i] - (x, y, z)|^2``, summed in coordinate order (every search here compares
    distances computed this way, so equal points give equal distances)."""
    return (points[i, 0] - x) ** 2 + (points[i, 1] - y) ** 2 + (points[i, 2] - z) ** 2


@kernel(inline=True)
def nearest(x, y, z, best, best_d2, tree, stack):
    """The nearest point to ``(x, y, z)``: ``(index, squared distance)``.

    Args:
        best, best_d2: a candidate (index, its squared distance) to start from, or ``(-1, inf)``.
        tree: the :class:`KDTree`.
        stack: a :class:`SearchScratch`.
    """
    tree_points, order, start, stop = tree.points, tree.order, tree.start, tree.stop
    stack_node, stack_bound, stack_offset = stack.node, stack.bound, stack.offset
    top = 0
    stack_node[0], stack_bound[0] = 0, 0.0
    stack_offset[0, 0], stack_offset[0, 1], stack_offset[0, 2] = 0.0, 0.0, 0.0
    while top >= 0:
        node, bound = stack_node[top], stack_bound[top]
        ox, oy, oz = stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2]
        top -= 1
        if bound > best_d2 * PRUNE_SLACK:
            continue
        node, top = _descend(node, bound, ox, oy, oz, x, y, z, best_d2 * PRUNE_SLACK, tree, stack,
                             top)
        for i in range(start[node], stop[node]):
            d2 = squared_distance(tree_points, i, x, y, z)
            if d2 <= best_d2:
                p = order[i]
                if d2 < best_d2 or p < best:
                    best, best_d2 = p, d2
    return best, best_d2


@kernel
def insert(d2, p, best_d2, best):
    """Insert point ``p`` at squared distance ``d2`` into the sorted list ``best_d2``, ``best``
    (k,) (by distance, then index), dropping its last entry; the caller has checked that
    ``(d2, p)`` precedes that entry."""
    j = len(best) - 1
    while j > 0 and (best_d2[j - 1] > d2 or (best_d2[j - 1] == d2 and best[j - 1] > p)):
        best_d2[j], best[j] = best_d2[j - 1], best[j - 1]
        j -= 1
    best_d2[j], best[j] = d2, p


@kernel(inline=True)
def k_nearest(x, y, z, best_d2, best, tree, stack):
    """The ``k`` nearest points to ``(x, y, z)``, written into ``best_d2``, ``best`` (k,): squared
    distances and indices, nearest first, ties by lower index; missing neighbours (k > N) stay
    ``inf`` and N. The lists are filled from scratch; the tree and scratch as in :func:`nearest`."""
    tree_points, order, start, stop = tree.points, tree.order, tree.start, tree.stop
    stack_node, stack_bound, stack_offset = stack.node, stack.bound, stack.offset
    n, last = len(tree_points), len(best) - 1
    best_d2[:] = np.inf
    best[:] = n
    worst_d2, worst = np.inf, n
    top = 0
    stack_node[0], stack_bound[0] = 0, 0.0
    stack_offset[0, 0], stack_offset[0, 1], stack_offset[0, 2] = 0.0, 0.0, 0.0
    while top >= 0:
        node, bound = stack_node[top], stack_bound[top]
        ox, oy, oz = stack_offset[top, 0], stack_offset[top, 1], stack_offset[top, 2]
        top -= 1
        if bound > worst_d2 * PRUNE_SLACK:
            continue
        node, top = _descend(node, bound, ox, oy, oz, x, y, z, worst_d2 * PRUNE_SLACK, tree, stack,
                             top)
        for i in range(start[node], stop[node]):
            d2 = squared_distance(tree_points, i, x, y, z)
            if d2 > worst_d2:
                continue
            p = order[i]
            if d2 == worst_d2 and p > worst:
                continue
            insert(d2, p, best_d2, best)
            worst_d2, worst = best_d2[last], best[last]
