"""Collision checks of a fitted grasp: the whole gripper against the object and obstacle planes.

:class:`CollisionChecker` (module :mod:`isf.collision.checker`) is the entry point. The other
modules are its parts: the gripper's geometry elements as surface patches (``_elements``), the
compiled body of a check (:mod:`isf.collision.kernel`), a signed distance from the tangent
planes of nearby object points (:mod:`isf.collision.surface_distance`), a voxel grid of the
space certainly outside a closed mesh (:mod:`isf.collision.voxels`) and the convex elements
with the object points inside them (:mod:`isf.collision.convex_elements`).
"""

from .checker import CollisionChecker, CollisionReport, Plane

__all__ = ["CollisionChecker", "CollisionReport", "Plane"]
