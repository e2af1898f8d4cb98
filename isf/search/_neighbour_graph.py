"""The Delaunay neighbour graph of a fixed point set, and the nearest-point walk on it.

ISF, the collision checks and the repair ask for the nearest object point of a query that lies
near the answer of an earlier query (the same contact point or gripper sample one step before).
A k-d tree answers such a query from its root every time; a walk on the Delaunay graph starts
at the earlier answer and is done in a step or two, several times cheaper than the tree's
search (``docs/benchmarks.md``).

Why the walk finds the nearest point: if a point ``v`` is not the nearest point of a query
``x``, shrink the ball about ``x`` through ``v`` towards ``v``, keeping ``v`` on its boundary,
until no point lies inside it. The empty ball then touches ``v`` and points that were strictly
inside the first ball (nearer to ``x`` than ``v``), and ``v`` shares a Delaunay edge with one
of them. So a point none of whose Delaunay neighbours is nearer is the nearest point.

The graph comes from Qhull (``scipy.spatial.Delaunay``) with its input joggled (option ``QJ``):
points on a lattice (a voxel-sampled box) are co-spherical in many places, where Qhull without
the joggle merges facets for a time that grows with the square of the point count. The
joggle moves the points by a tiny random amount (Qhull sizes it from its rounding error), so
the graph is the Delaunay graph of points that close to these. Hence the searches built on it
(:func:`isf.search.nearest.nearest_point`):

* a walk that meets a tie (a neighbour exactly as near as the point it stops at, which on a
  lattice the joggle may have left unconnected to a nearer point) hands the query to the k-d
  tree, which resolves ties to the lowest index;
* otherwise its answer is the tree's unless some point is nearer than it by less than the
  joggle, which no test or benchmark here has met (``tests/test_nearest.py`` compares them on
  lattices, duplicates and surface samples; over 10^6 queries on YCB and lattice objects
  agreed in the development of this module).

Each point's neighbours are listed nearest first, with a *cutoff* per listed neighbour: a walk
at point ``v``, whose distance ``r`` from the query is less than half the distance ``e`` from
``v`` to its next listed neighbour, skips that neighbour and the rest. Each of them is farther
from the query than ``e - r > r``, so it can neither be a step of the walk nor tie with ``v``.
On the fits of ``bench/bench_rounds.py`` a walk then reads 10.1 neighbours instead of 19.6
(a point has 15 neighbours on average, and a walk visits 1.28 points). Of neighbours equally
near the query, a step takes the one listed first; where the walk ends does not depend on it.

Exact duplicates are triangulated once (see :func:`neighbour_graph`).
When Qhull cannot triangulate the points, or they are fewer than 5, more than
:data:`MAX_POINTS`, or lie in one plane (to within :data:`FLAT` of their extent, where the
joggle would decide the graph), there is no graph (empty arrays) and the searches use the k-d
tree alone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import Delaunay, QhullError

from ..compiled.kernels import kernel
from .kdtree import squared_distance

__all__ = ["CUTOFF_MARGIN", "FLAT", "MAX_POINTS", "NO_GRAPH", "QHULL_OPTIONS", "NeighbourGraph",
           "neighbour_graph", "walk"]


class NeighbourGraph(NamedTuple):
    """The Delaunay neighbours of N points (:func:`neighbour_graph`), E neighbour entries."""

    indptr: np.ndarray
    """Where each point's neighbours start in ``indices``, (N + 1,) int64 ((0,) without a graph)."""
    indices: np.ndarray
    """The neighbours, each point's nearest to it first, (E,) int64."""
    cutoff: np.ndarray
    """A quarter of the squared distance between each point and its neighbour, less
    :data:`CUTOFF_MARGIN`, (E,) float64, m^2."""


NO_GRAPH = NeighbourGraph(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
"""The graph of a point set without one (empty arrays)."""

CUTOFF_MARGIN = 1e-9
"""The cutoffs' relative margin. A neighbour is skipped only when it is farther from the
query than the current point by this fraction of that point's distance at least, far more
than the rounding of any squared distance (a few 1e-16), so the computed distances order the
skipped neighbours after the current point as the exact ones do."""

QHULL_OPTIONS = "QJ Qbb"
"""The options given to Qhull. ``QJ`` joggles the input (a triangulation, and no slow merging
of co-spherical facets); ``Qbb`` scales the lifted coordinate to the others' range (fewer
precision problems)."""


FLAT = 1e-6
"""Points whose thinnest extent is below this fraction of their widest get no graph."""

MAX_POINTS = 20_000
"""The most points a graph is built for. Qhull's time grows with the point count, and
planning matches against a working surface of a few thousand points whatever the object's size
(:func:`isf.planning._working_surface.working_surface`)."""


def neighbour_graph(points: np.ndarray) -> NeighbourGraph:
    """The Delaunay neighbours of each point (N, 3) (:class:`NeighbourGraph`): those of point
    ``i`` are ``indices[indptr[i]:indptr[i + 1]]``, nearest to point ``i`` first, and
    ``cutoff[j]`` is a quarter of the squared distance (m^2) between point ``i`` and its
    neighbour ``indices[j]``, less :data:`CUTOFF_MARGIN`. :data:`NO_GRAPH` when Qhull cannot
    triangulate the points, or they are more than :data:`MAX_POINTS`.

    Exact duplicates are triangulated once, as the first of them; each other copy gets that
    point and its neighbours as neighbours (a walk may start there) and is no one's neighbour
    (a walk ends at the first copy, the lowest index, as the tree's answer does).
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) > MAX_POINTS:
        return NO_GRAPH
    unique, first, copy_of = np.unique(points, axis=0, return_index=True, return_inverse=True)
    copy_of = first[copy_of.reshape(-1)]  # each point's first copy
    if len(unique) < 5:
        return NO_GRAPH
    spread = np.linalg.svd(unique - unique.mean(axis=0), compute_uv=False)
    if not spread[2] > FLAT * spread[0]:  # (nearly) in one plane: the joggle would decide the graph
        return NO_GRAPH
    kept = np.sort(first)  # the points triangulated: the first copy of each
    try:
        triangulation = Delaunay(points[kept], qhull_options=QHULL_OPTIONS)
    except (QhullError, ValueError):
        return NO_GRAPH
    if len(triangulation.coplanar):  # a point left out of the triangulation: no walk reaches it
        return NO_GRAPH
    indptr, indices = triangulation.vertex_neighbor_vertices
    indices = kept[indices]
    if len(kept) == len(points):
        return NeighbourGraph(*_nearest_first(points, indptr.astype(np.int64),
                                              indices.astype(np.int64)))
    row = np.full(len(points), -1, np.int64)
    row[kept] = np.arange(len(kept))
    lists = []
    for i in range(len(points)):
        r = row[copy_of[i]]
        own = indices[indptr[r]:indptr[r + 1]]
        lists.append(own if i == copy_of[i] else np.concatenate(([copy_of[i]], own)))
    counts = np.array([len(n) for n in lists], dtype=np.int64)
    indptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return NeighbourGraph(*_nearest_first(points, indptr, np.concatenate(lists).astype(np.int64)))


@kernel
def _nearest_first(points, indptr, indices):
    """The graph ``(indptr, indices)`` with each point's neighbours sorted by their distance from
    it (insertion sort, stable: the lists are short), and the walk's cutoffs (see
    :func:`neighbour_graph`)."""
    ordered, squared = indices.copy(), np.empty(len(indices))
    for i in range(len(indptr) - 1):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        for j in range(indptr[i], indptr[i + 1]):
            w = ordered[j]
            d2 = squared_distance(points, w, x, y, z)
            k = j
            while k > indptr[i] and squared[k - 1] > d2:
                ordered[k], squared[k] = ordered[k - 1], squared[k - 1]
                k -= 1
            ordered[k], squared[k] = w, d2
    return indptr, ordered, squared * (0.25 * (1.0 - CUTOFF_MARGIN))


@kernel(inline=True)
def walk(x, y, z, start, points, graph):
    """The nearest point to ``(x, y, z)`` by a walk from point ``start`` on the
    :class:`NeighbourGraph` ``graph``: ``(index, squared distance, tied)``. Each step moves to the
    nearest neighbour while it is nearer than the current point (neighbours past the cutoff are
    farther); ``tied``: the point it stops at has a neighbour exactly as near (the answer is then
    not settled)."""
    indptr, indices, cutoff = graph.indptr, graph.indices, graph.cutoff
    v = start
    dv = squared_distance(points, v, x, y, z)
    while True:
        best, best_d2, tied = v, dv, False
        for j in range(indptr[v], indptr[v + 1]):
            if dv < cutoff[j]:  # this neighbour and the rest are farther than v
                break
            w = indices[j]
            d2 = squared_distance(points, w, x, y, z)
            if d2 < best_d2:
                best, best_d2 = w, d2
            elif d2 == dv:
                tied = True
        if best == v:
            return v, dv, tied
        v, dv = best, best_d2
