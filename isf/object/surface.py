"""The :class:`ObjectSurface`: an object's surface as points with outward normals.

Frame: ``object``, the frame of the input mesh or cloud (after scaling to metres).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..search.nearest import NearestPoints

__all__ = ["ObjectSurface"]


@dataclass(eq=False)
class ObjectSurface:
    """Surface samples of a workpiece, with a nearest-point search built on first use.

    Attributes:
        points: surface points in the object frame, shape (N, 3), metres.
        normals: unit outward normals, shape (N, 3).
        spacing: typical distance between neighbouring points, metres.
        name: where it came from (file name or a description).
        mesh_vertices: the source mesh's vertices (scaled, object frame), shape (V, 3),
            or None for a point cloud.
        mesh_faces: the source mesh's triangles, shape (F, 3), or None.
        viewpoints: for what cameras saw (a scene's surface, :mod:`isf.scene`), the camera
            positions, shape (C, 3), metres: the normals face them and the surface continues
            unseen behind; None for an object.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float
    name: str = "object"
    mesh_vertices: np.ndarray | None = None
    mesh_faces: np.ndarray | None = None
    viewpoints: np.ndarray | None = None
    _search: NearestPoints | None = field(init=False, repr=False, default=None)
    _thinned: dict = field(init=False, repr=False, default_factory=dict)  # see working_surface

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float64)
        if self.mesh_faces is not None:
            self.mesh_vertices = np.asarray(self.mesh_vertices, dtype=np.float64)
            self.mesh_faces = np.asarray(self.mesh_faces, dtype=np.int64)

    @property
    def n_points(self) -> int:
        """Number of surface points."""
        return len(self.points)

    @property
    def centroid(self) -> np.ndarray:
        """Mean of the surface points, shape (3,), metres (object frame)."""
        return self.points.mean(axis=0)

    @property
    def is_mesh(self) -> bool:
        """True when the surface came from a triangle mesh (not a point cloud)."""
        return self.mesh_faces is not None

    @property
    def search(self) -> NearestPoints:
        """The exact nearest-point search on :attr:`points`, with their Delaunay graph (built on
        first use)."""
        if self._search is None:
            self._search = NearestPoints(self.points, graph=True)
        return self._search

    def nearest(
        self, query: np.ndarray, guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nearest surface point of each query point (exact; see :mod:`isf.search.nearest`).

        Args:
            query: points in the object frame, shape (M, 3), metres.
            guess: optional index per query (M,) of a point likely to be near (-1 for none),
                e.g. the previous iteration's answer; it only speeds the search.

        Returns:
            (distances (M,) in metres, indices (M,) into :attr:`points`; the lowest index
            among equally near points).
        """
        return self.search.query(query, guess)
