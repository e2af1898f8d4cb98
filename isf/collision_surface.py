"""A signed-distance estimate from the tangent planes of nearby surface points.

A query point's signed distance is the largest of ``(p - o_k) . n_k`` over its
:data:`NEIGHBOURS` nearest surface points ``o_k`` with outward normals ``n_k``: a point is
inside only when it lies below every nearby tangent plane (see :mod:`isf.collision`).
"""

from __future__ import annotations

import weakref

import numpy as np
import trimesh
from numba import njit

from .nearest import NearestPoints

NEIGHBOURS = 6  # tangent planes of the nearest surface points a point must lie below to be inside


@njit(cache=True, error_model="numpy")
def _highest_planes(query, points, normals, idx):
    """Per query point (M, 3): the largest height ``(p - o_k) . n_k`` over its neighbours
    ``idx`` (M, K) (the first of equal ones), (M,), and the index of that neighbour, (M,)."""
    m, k = idx.shape
    height, best = np.empty(m), np.empty(m, np.int64)
    for q in range(m):
        height[q], best[q] = -np.inf, idx[q, 0]
        for j in range(k):
            o = idx[q, j]
            h = ((query[q, 0] - points[o, 0]) * normals[o, 0]
                 + (query[q, 1] - points[o, 1]) * normals[o, 1]
                 + (query[q, 2] - points[o, 2]) * normals[o, 2])
            if h > height[q]:
                height[q], best[q] = h, o
    return height, best


class TangentPlanes:
    """Surface points (M, 3) with outward unit normals (M, 3), ``spacing`` metres apart."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, spacing: float):
        self.points = np.ascontiguousarray(points, dtype=float)
        self.normals = np.ascontiguousarray(normals, dtype=float)
        self.spacing = float(spacing)
        """Typical distance between neighbouring points, metres."""
        self.tree = NearestPoints(self.points)
        """Exact nearest-neighbour search on ``points``."""

    def evaluate(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance of points (M, 3), metres (M,), negative inside; the normal of the
        tangent plane that sets it (its gradient), (M, 3); the distance to the nearest surface
        point, metres (M,), and that point, (M, 3)."""
        if len(query) == 0:
            return np.empty(0), np.empty((0, 3)), np.empty(0), np.empty((0, 3))
        k = min(NEIGHBOURS, len(self.points))
        query = np.ascontiguousarray(query, dtype=np.float64)
        dist, idx = self.tree.query_k(query, k)
        height, best = _highest_planes(query, self.points, self.normals, idx)
        return height, self.normals[best], dist[:, 0], self.points[idx[:, 0]]

    def signed_distance(self, query: np.ndarray) -> np.ndarray:
        """Estimated signed distance of points (M, 3), metres (M,), negative inside."""
        return self.evaluate(query)[0]

    def depth(self, query: np.ndarray) -> float:
        """Deepest of the points (M, 3) below the surface, metres (0 if none)."""
        sd = self.signed_distance(query)
        return float(max(0.0, -sd.min())) if len(sd) else 0.0


_MESH_MEMOS: dict[int, tuple[weakref.ref, weakref.ref, dict]] = {}


def mesh_memo(obj) -> dict:
    """A dict for what is derived from a mesh object's arrays (``obj.mesh_vertices``,
    ``obj.mesh_faces``, treated as immutable), kept while those arrays live: the collision
    checker and the repair of every plan on the object, or on its thinned working surface
    (which shares them), build it once. ``obj``: an :class:`isf.ObjectSurface` with a mesh."""
    vertices, faces = obj.mesh_vertices, obj.mesh_faces
    entry = _MESH_MEMOS.get(id(faces))
    if entry is not None and entry[0]() is faces and entry[1]() is vertices:
        return entry[2]
    memo: dict = {}
    _MESH_MEMOS[id(faces)] = (weakref.ref(faces), weakref.ref(vertices), memo)
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
