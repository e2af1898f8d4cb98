"""Exact nearest-neighbour queries on a fixed point set.

ISF asks one question of the object again and again (the nearest surface point of each
contact point, about a million times per plan), on a point set that never changes.
:class:`NearestPoints` answers it with a k-d tree (:mod:`isf.search.kdtree`) built once and searched
in compiled code (one call per batch of queries, no Python per query). A search can start from
a guess (the point found for the same query in the previous ISF iteration). Built with
``graph=True``, the search also holds the points' Delaunay graph
(:mod:`isf.search._neighbour_graph`), and a search with a guess walks the graph from it instead of
descending the tree: a query near its guess costs a step or two. The answer is exact either
way (up to the joggle of the graph's points, see :mod:`isf.search._neighbour_graph`): the nearest
distance and, among equally near points, the lowest index.
:meth:`NearestPoints.query_k` answers the k nearest points with the tree (the collision checks
and the collision repair ask for the tangent planes of the 6 nearest).

Compiled callers search per query with :func:`nearest_point` (or
:func:`isf.search.kdtree.k_nearest`) on :attr:`NearestPoints.tree`.
"""

from __future__ import annotations

import threading
from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel
from ..compiled.leaf import leaf
from . import kdtree
from ._neighbour_graph import NO_GRAPH, NeighbourGraph, neighbour_graph, walk

__all__ = ["NearestPoints", "SearchArrays", "nearest_point", "search_scratch", "tree_nearest"]


class SearchArrays(NamedTuple):
    """The arrays of a nearest-point search (:attr:`NearestPoints.tree`)."""

    kd: kdtree.KDTree
    """The k-d tree of the points (:func:`isf.search.kdtree.build`)."""
    graph: NeighbourGraph
    """The points' Delaunay graph (:func:`isf.search._neighbour_graph.neighbour_graph`); empty
    arrays (:data:`isf.search._neighbour_graph.NO_GRAPH`) without one."""


@kernel(error_model="python")
def search_scratch():
    """The scratch of a tree search (:class:`isf.search.kdtree.SearchScratch`)."""
    size = kdtree.STACK_SIZE
    return kdtree.SearchScratch(np.empty(size, np.int64), np.empty(size), np.empty((size, 3)))


@leaf
def nearest_point(x, y, z, guess, points, tree, scratch, limit):
    """The nearest point to ``(x, y, z)`` closer than ``sqrt(limit)``: ``(index, squared
    distance)``, exact; ``(-1, limit)`` when there is none (``limit = inf``: the nearest point).

    Args:
        guess: a point index to start from, or -1: the graph is walked from it when there is
            one (:func:`isf.search._neighbour_graph.walk`; the tree settles a walk that meets a tie),
            else it bounds the tree's search (:func:`tree_nearest`).
        points, tree: :attr:`NearestPoints.points` and :attr:`NearestPoints.tree`.
        scratch: :func:`search_scratch`.
        limit: squared search radius, m^2.
    """
    if guess >= 0 and len(tree.graph.indptr):
        found, found_d2, tied = walk(x, y, z, guess, points, tree.graph)
        if not tied:
            return (found, found_d2) if found_d2 < limit else (-1, limit)
        guess = found  # a tie: the tree settles it, bounded by the walk's answer
    return tree_nearest(x, y, z, guess, points, tree, scratch, limit)


@leaf
def tree_nearest(x, y, z, bound, points, tree, scratch, limit):
    """:func:`nearest_point` by the k-d tree alone, its search bounded from the start by the
    distance of point ``bound`` (-1: none; ignored when not closer than the limit)."""
    best, best_d2 = -1, limit
    if bound >= 0:
        d2 = kdtree.squared_distance(points, bound, x, y, z)
        if d2 < limit:
            best, best_d2 = bound, d2
    return kdtree.nearest(x, y, z, best, best_d2, tree.kd, scratch)


@kernel
def nearest_with_guesses(queries, guess, limit, points, tree):
    """:func:`nearest_point` of each query (M, 3) with its guess (M,) within the squared radius
    ``limit``: distances (M,), indices (M,); ``inf`` and -1 where no point is that close. A query
    without a guess searches the tree bounded by the previous query's answer (queries often
    come in runs; a walk from there could cross the object when they do not)."""
    m = len(queries)
    distance, index = np.full(m, np.inf), np.full(m, -1, np.int64)
    scratch = search_scratch()
    for q in range(m):
        x, y, z = queries[q, 0], queries[q, 1], queries[q, 2]
        if guess[q] >= 0:
            best, d2 = nearest_point(x, y, z, guess[q], points, tree, scratch, limit)
        else:
            best, d2 = tree_nearest(x, y, z, index[q - 1] if q > 0 else -1, points, tree, scratch,
                                    limit)
        if best >= 0:
            distance[q], index[q] = np.sqrt(d2), best
    return distance, index


@kernel
def _query_k(queries, k, tree):
    """The k nearest points of each query (M, 3) (:func:`isf.search.kdtree.k_nearest`): distances
    (M, k), indices (M, k)."""
    m = len(queries)
    distance, index = np.empty((m, k)), np.empty((m, k), np.int64)
    best_d2, best = np.empty(k), np.empty(k, np.int64)
    scratch = search_scratch()
    for q in range(m):
        kdtree.k_nearest(queries[q, 0], queries[q, 1], queries[q, 2], best_d2, best, tree.kd, scratch)
        for j in range(k):
            distance[q, j], index[q, j] = np.sqrt(best_d2[j]), best[j]
    return distance, index


class NearestPoints:
    """Exact nearest-neighbour search on a fixed point set.

    Args:
        points: the points, (N, 3), N >= 1.
        leaf_size: points per leaf of the k-d tree at most (:data:`isf.search.kdtree.LEAF_SIZE` by
            default). It changes the speed, never an answer: larger leaves suit queries that
            lie farther from the points than their spacing (on a dense surface sample).
        graph: also build the points' Delaunay graph (:mod:`isf.search._neighbour_graph`), so
            that searches from a guess walk it. It changes the speed, not the answers (but see
            the joggle in :mod:`isf.search._neighbour_graph`).
    """

    def __init__(self, points: np.ndarray, leaf_size: int = kdtree.LEAF_SIZE, graph: bool = False):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        """The points, (N, 3)."""
        if self.points.ndim != 2 or self.points.shape[1] != 3 or not len(self.points):
            raise ValueError(f"need points of shape (N, 3) with N >= 1, got {self.points.shape}")
        if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or leaf_size < 1:
            raise ValueError(f"leaf_size must be a positive integer, got {leaf_size!r}")
        self.tree = SearchArrays(kdtree.build(self.points, int(leaf_size)), NO_GRAPH)
        """The arrays of the search (:class:`SearchArrays`), for :func:`nearest_point` and
        (its ``kd``) :func:`isf.search.kdtree.k_nearest`. :meth:`add_graph` replaces the tuple
        (never changes its arrays), so a search that holds the old tuple stays valid."""
        self._graph_lock = threading.Lock()
        self._graph_tried = False
        if graph:
            self.add_graph()

    @property
    def has_graph(self) -> bool:
        """Whether searches from a guess walk the Delaunay graph."""
        return len(self.tree.graph.indptr) > 0

    def add_graph(self) -> bool:
        """Build the points' Delaunay graph (:mod:`isf.search._neighbour_graph`),
        if no call did before, and let searches from a guess walk it. Returns whether the search
        has a graph (points in one plane, too few or too many get none). Thread-safe: while
        one thread builds, a call from another returns at once (False) and its searches use the
        tree."""
        if not self._graph_lock.acquire(blocking=False):
            return False
        try:
            if not self._graph_tried:
                self._graph_tried = True
                self.tree = self.tree._replace(graph=neighbour_graph(self.points))
        finally:
            self._graph_lock.release()
        return self.has_graph

    def query(self, queries: np.ndarray, guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Nearest point of each query point.

        Args:
            queries: query points, (M, 3).
            guess: optional candidate index per query (M,) (-1 for none), e.g. the answer of a
                previous query from nearby; it speeds the search and never changes its answer.
                A query without one searches the tree bounded by the previous query's answer
                (queries often come in runs of neighbours, such as samples along a surface).

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
                    guess.min() >= -1 and guess.max() < len(self.points))):
                raise ValueError(f"guess must hold one index in [-1, {len(self.points) - 1}] per "
                                 f"query ({len(queries)}); pass None for no guesses")
        return nearest_with_guesses(queries, guess, np.inf, self.points, self.tree)

    def query_within(self, queries: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Nearest point of each query point, among the points closer than ``radius`` metres.

        Far cheaper than :meth:`query` for queries far from every point: the radius bounds the
        search from the start.

        Args:
            queries: query points, (M, 3).
            radius: search radius, metres, > 0.

        Returns:
            distances (M,) and indices (M,) as :meth:`query` gives them where the nearest point
            lies closer than ``radius``; ``inf`` and -1 elsewhere.
        """
        if not radius > 0.0:
            raise ValueError(f"radius must be > 0, got {radius!r}")
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        return nearest_with_guesses(queries, np.full(len(queries), -1, dtype=np.int64), float(radius) ** 2,
                      self.points, self.tree)

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
        return _query_k(queries, int(k), self.tree)
