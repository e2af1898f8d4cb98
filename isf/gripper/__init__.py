"""Grippers: the :class:`Gripper` model and loading it from a tagged URDF.

:func:`load_gripper` (module :mod:`isf.gripper.loading`) reads a URDF's text and ``isf:*`` tags
(:mod:`isf.gripper.urdf_tags`), builds the Pinocchio model (:mod:`isf.gripper.urdf_model`),
resolves mesh paths (:mod:`isf.gripper.mesh_paths`) and samples the tagged contact surfaces
(:mod:`isf.gripper.surface_sampling`); :mod:`isf.gripper.chain` evaluates the kinematics in
compiled code; :mod:`isf.gripper.bundled` lists the grippers shipped with isf;
:mod:`isf.gripper.yourdfpy_reading` reads a URDF with yourdfpy, without its log, for the link
meshes the viewer draws and the simulation collides.
"""

from ..exports import lazy_exports

_SOURCES = {  # each public name -> the module of this package that defines it (loaded on use)
    "ContactSurface": "model",
    "Gripper": "model",
    "LinkGeometry": "model",
    "inspect_gripper": "loading",
    "load_gripper": "loading",
}

__all__ = sorted(_SOURCES)  # noqa: PLE0605 (computed: the keys above)
__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
