"""A signed-distance estimate from the tangent planes of nearby surface points.

A query point's signed distance is the largest of ``(p - o_k) . n_k`` over its
``NEIGHBOURS`` (6) nearest surface points ``o_k`` with outward normals ``n_k``: a point is
inside only when it lies below every nearby tangent plane (see :mod:`isf.collision.checker`).
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import numpy as np
import trimesh

from ..compiled.kernels import kernel
from ..search import kdtree
from ..search.nearest import NearestPoints, search_scratch

NEIGHBOURS = 6  # tangent planes of the nearest surface points a point must lie below to be inside
TREE_LEAF_SIZE = 32
"""The leaf size of a surface's k-d tree. The checks and the repair query points millimetres
to centimetres from a dense surface sample, where larger leaves than the default answer faster
(the same answers; ``docs/benchmarks.md``)."""
GRAPH_PAYBACK = 600
"""Searches per point after which a deferred Delaunay graph (:class:`TangentPlanes`) is built:
the number at which the time a walk saves per search (a repair search of a resampled mesh's
dense planes) adds up to the graph's cost per point (``docs/benchmarks.md``). Building it then
(the ski-rental rule), a single plan does without the graph and a series of plans pays at most
about twice the better choice in hindsight."""


@kernel(inline=True)
def estimate(x, y, z, best_d2, best, points, normals, tree, stack):
    """The signed distance estimate at ``(x, y, z)``: ``(height, plane, distance, nearest)``: the
    largest height ``(p - o_k) . n_k`` over the ``len(best)`` nearest ``points`` (the first of equal
    ones), the index of the point whose plane sets it, the distance to the nearest point and its
    index. ``best_d2``, ``best``: scratch of the neighbour count; the tree
    (:class:`isf.search.kdtree.KDTree`) and the search scratch as for
    :func:`isf.search.kdtree.k_nearest`."""
    kdtree.k_nearest(x, y, z, best_d2, best, tree, stack)
    height, plane = -np.inf, best[0]
    for j in range(len(best)):
        o = best[j]
        h = ((x - points[o, 0]) * normals[o, 0] + (y - points[o, 1]) * normals[o, 1]
             + (z - points[o, 2]) * normals[o, 2])
        if h > height:
            height, plane = h, o
    return height, plane, np.sqrt(best_d2[0]), best[0]


@kernel
def plane_estimates(query, points, normals, tree, k):
    """:func:`estimate` with ``k`` neighbours of each query point (M, 3): four (M,) arrays.
    ``tree``: :attr:`isf.search.nearest.NearestPoints.tree` of ``points``."""
    m = len(query)
    height, plane, distance, nearest = np.empty(m), np.empty(m, np.int64), np.empty(m), np.empty(m, np.int64)
    stack = search_scratch()
    best_d2, best = np.empty(k), np.empty(k, np.int64)
    for q in range(m):
        height[q], plane[q], distance[q], nearest[q] = estimate(
            query[q, 0], query[q, 1], query[q, 2], best_d2, best, points, normals, tree.kd, stack)
    return height, plane, distance, nearest


class TangentPlanes:
    """Surface points (M, 3) with outward unit normals (M, 3), ``spacing`` metres apart.

    ``graph``: the search also walks the points' Delaunay graph from a guess
    (:class:`isf.search.nearest.NearestPoints`), worth its set-up where many searches start near
    their answer: ``True`` builds it now, ``"deferred"`` once the searches counted by
    :meth:`note_searches` reach :data:`GRAPH_PAYBACK` per point. ``search``: an existing
    search on the same points to use instead of building one (e.g. the object's own,
    :attr:`isf.ObjectSurface.search`).
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, spacing: float,
                 graph: bool | str = False, search: NearestPoints | None = None):
        self.points = np.ascontiguousarray(points, dtype=float)
        self.normals = np.ascontiguousarray(normals, dtype=float)
        self.spacing = float(spacing)
        """Typical distance between neighbouring points, metres."""
        if search is not None and not np.array_equal(search.points, self.points):
            raise ValueError("search must be built on the same points")
        if graph not in (True, False, "deferred"):
            raise ValueError(f"graph must be True, False or 'deferred', got {graph!r}")
        self.tree = NearestPoints(self.points, leaf_size=TREE_LEAF_SIZE, graph=graph is True) \
            if search is None else search
        """Exact nearest-neighbour search on ``points``."""
        self._searches_before_graph = GRAPH_PAYBACK * len(self.points) if graph == "deferred" \
            else np.inf

    def note_searches(self, count: int) -> None:
        """Count ``count`` searches from guesses that a caller makes on :attr:`tree`; a deferred
        graph is built once they reach :data:`GRAPH_PAYBACK` per point."""
        self._searches_before_graph -= count
        if self._searches_before_graph <= 0:
            self._searches_before_graph = np.inf  # built here, or being built by another thread
            self.tree.add_graph()

    def evaluate(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance of points (M, 3), metres (M,), negative inside; the normal of the
        tangent plane that sets it (its gradient), (M, 3); the distance to the nearest surface
        point, metres (M,), and that point, (M, 3)."""
        if len(query) == 0:
            return np.empty(0), np.empty((0, 3)), np.empty(0), np.empty((0, 3))
        k = min(NEIGHBOURS, len(self.points))
        query = np.ascontiguousarray(query, dtype=np.float64)
        height, plane, distance, nearest = plane_estimates(query, self.points, self.normals,
                                                           self.tree.tree, k)
        return height, self.normals[plane], distance, self.points[nearest]

    def signed_distance(self, query: np.ndarray) -> np.ndarray:
        """Estimated signed distance of points (M, 3), metres (M,), negative inside."""
        sd, _, _, _ = self.evaluate(query)
        return sd

    def depth(self, query: np.ndarray) -> float:
        """Deepest of the points (M, 3) below the surface, metres (0 if none)."""
        sd = self.signed_distance(query)
        return float(max(0.0, -sd.min())) if len(sd) else 0.0


class _MeshMemo(NamedTuple):
    """A mesh's memo (:func:`mesh_memo`) with weak references to the arrays it is keyed on."""

    faces: weakref.ref
    vertices: weakref.ref
    memo: dict


_MESH_MEMOS: dict[int, _MeshMemo] = {}


def mesh_memo(obj) -> dict:
    """A dict for what is derived from a mesh object's arrays (``obj.mesh_vertices``,
    ``obj.mesh_faces``, treated as immutable), kept while those arrays live: the collision
    checker and the repair of every plan on the object, or on its thinned working surface
    (which shares them), build it once. ``obj``: an :class:`isf.ObjectSurface` with a mesh."""
    vertices, faces = obj.mesh_vertices, obj.mesh_faces
    entry = _MESH_MEMOS.get(id(faces))
    if entry is not None and entry.faces() is faces and entry.vertices() is vertices:
        return entry.memo
    memo: dict = {}
    _MESH_MEMOS[id(faces)] = _MeshMemo(weakref.ref(faces), weakref.ref(vertices), memo)
    weakref.finalize(faces, _MESH_MEMOS.pop, id(faces), None)
    return memo


def closed_mesh(obj) -> trimesh.Trimesh | None:
    """The object's mesh when it is closed and outward (watertight, consistent winding, positive
    volume), so that it can be resampled densely for inside/outside tests; else None (a point
    cloud, or an open or inward mesh). ``obj``: an :class:`isf.ObjectSurface`."""
    if not obj.is_mesh:
        return None
    memo = mesh_memo(obj)
    if "closed" not in memo:
        # copies: the memo must not keep the arrays it is keyed on alive
        mesh = trimesh.Trimesh(np.array(obj.mesh_vertices, float), np.array(obj.mesh_faces, np.int64),
                               process=False, validate=False)
        closed = mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        memo["closed"] = mesh if closed else None
    return memo["closed"]
