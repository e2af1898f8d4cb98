"""Exact nearest-point search on fixed point sets, and grids over them.

:class:`NearestPoints` (module :mod:`isf.search.nearest`) answers nearest and k-nearest queries
with a compiled k-d tree (:mod:`isf.search.kdtree`) or walks on the Delaunay neighbour graph
(``_neighbour_graph``); :class:`PointGrid` bins points for ball queries; :mod:`isf.search.voxel_grid`
labels points by voxel.
"""

from .nearest import NearestPoints
from .point_grid import PointGrid

__all__ = ["NearestPoints", "PointGrid"]
