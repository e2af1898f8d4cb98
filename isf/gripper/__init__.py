"""Grippers: the :class:`Gripper` model and loading it from a tagged URDF.

:func:`load_gripper` (module :mod:`isf.gripper.loading`) reads a URDF's text and ``isf:*`` tags
(:mod:`isf.gripper.urdf_tags`), builds the Pinocchio model (:mod:`isf.gripper.urdf_model`),
resolves mesh paths (:mod:`isf.gripper.mesh_paths`) and samples the tagged contact surfaces
(:mod:`isf.gripper.surface_sampling`); :mod:`isf.gripper.chain` evaluates the kinematics in
compiled code; :mod:`isf.gripper.bundled` lists the grippers shipped with isf.
"""

from .loading import inspect_gripper, load_gripper
from .model import ContactSurface, Gripper, LinkGeometry

__all__ = ["ContactSurface", "Gripper", "LinkGeometry", "inspect_gripper", "load_gripper"]
