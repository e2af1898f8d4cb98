"""isf: grasp planning for customized grippers by Iterative Surface Fitting.

Fan, Lin, Tang, Tomizuka, "Grasp Planning for Customized Grippers by Iterative
Surface Fitting", CASE 2018, generalised to any URDF gripper whose contact
surfaces are tagged in the file.

Frames: ``T_a_b`` is the pose of frame ``b`` in frame ``a`` (it maps points
expressed in ``b`` into ``a``). The ``object`` frame is the frame of the object
file; the ``gripper`` frame is the URDF's root link.

The public names below load on first use (:pep:`562`): ``import isf`` stays fast, and a
command that needs no kernels (``isf --help``) loads none of numba, Pinocchio or trimesh.
"""

from __future__ import annotations

from .exports import lazy_exports

__version__ = "0.1.0"

_SOURCES = {  # each public name -> the module (relative to isf) that defines it
    "AssetFetchError": "exceptions",
    "CameraIntrinsics": "scene",
    "CentringConfig": "planning.centring",
    "CollisionChecker": "collision.checker",
    "CollisionReport": "collision.checker",
    "ConfigError": "exceptions",
    "ContactSurface": "gripper.model",
    "Diversity": "planning.diversity",
    "FitConfig": "config",
    "FitResult": "result",
    "FitStatus": "result",
    "GeometryLoadError": "exceptions",
    "Grasp": "planning.planner",
    "Gripper": "gripper.model",
    "GripperDescriptionError": "exceptions",
    "ISFError": "exceptions",
    "ISFWarning": "exceptions",
    "InvalidInputError": "exceptions",
    "IterationRecord": "result",
    "JointLimitError": "exceptions",
    "JointLimitViolation": "exceptions",
    "MeshNotFoundError": "exceptions",
    "ModelBuildError": "exceptions",
    "ObjectLoadError": "exceptions",
    "ObjectSizeWarning": "exceptions",
    "ObjectSurface": "object.surface",
    "Outcome": "samplers",
    "OutputFileError": "exceptions",
    "PlanResult": "planning.planner",
    "PlanStats": "planning.planner",
    "Plane": "collision.checker",
    "PluginLoadError": "exceptions",
    "QualityConfig": "quality",
    "Proposal": "samplers",
    "QPStepError": "exceptions",
    "RegistrationError": "exceptions",
    "RepairConfig": "repair.clearance",
    "Sampler": "samplers",
    "SamplerNotFound": "exceptions",
    "Scene": "scene",
    "SceneView": "scene",
    "SurfaceSelectionError": "exceptions",
    "URDFReadError": "exceptions",
    "UnknownAssetError": "exceptions",
    "YCBNotFoundError": "exceptions",
    "available_samplers": "samplers",
    "fit": "fitting.fit",
    "fit_many": "fitting.fit",
    "get_sampler": "samplers",
    "grasp_quality": "quality",
    "inspect_gripper": "gripper.loading",
    "load_dataset": "batch",
    "load_gripper": "gripper.loading",
    "load_object": "object.loading",
    "load_scene": "scene",
    "open_object": "object.specs",
    "plan": "planning.planner",
    "register_sampler": "samplers",
    "run_batch": "batch",
    "validate_plan": "simulation",
}

__all__ = sorted([*_SOURCES, "__version__"])  # noqa: PLE0605 (a new name is one line above)


__getattr__, __dir__ = lazy_exports(__name__, _SOURCES)
