"""isf: grasp planning for customized grippers by Iterative Surface Fitting.

Fan, Lin, Tang, Tomizuka, "Grasp Planning for Customized Grippers by Iterative
Surface Fitting", CASE 2018, generalised to any URDF gripper whose contact
surfaces are tagged in the file.

Frames: ``T_a_b`` is the pose of frame ``b`` in frame ``a`` (it maps points
expressed in ``b`` into ``a``). The ``object`` frame is the frame of the object
file; the ``gripper`` frame is the URDF's root link.
"""

__version__ = "0.1.0"

from .compiled.cache import refresh_installed as _refresh_kernel_cache

_refresh_kernel_cache()  # before any kernel loads: drop cached kernels whose sources changed

from .collision.checker import CollisionChecker, CollisionReport, Plane
from .config import FitConfig
from .exceptions import (
    AssetFetchError,
    ConfigError,
    GeometryLoadError,
    GripperDescriptionError,
    InvalidInputError,
    ISFError,
    ISFWarning,
    JointLimitError,
    JointLimitViolation,
    MeshNotFoundError,
    ModelBuildError,
    ObjectLoadError,
    PluginLoadError,
    QPStepError,
    RegistrationError,
    SamplerNotFound,
    SurfaceSelectionError,
    UnknownAssetError,
    URDFReadError,
    YCBNotFoundError,
)
from .fitting.fit import fit, fit_many
from .gripper.loading import inspect_gripper, load_gripper
from .gripper.model import ContactSurface, Gripper
from .object.loading import load_object
from .object.specs import open_object
from .object.surface import ObjectSurface
from .planning.planner import Grasp, PlanResult, PlanStats, plan
from .repair.clearance import RepairConfig
from .result import FitResult, FitStatus, IterationRecord
from .samplers import Outcome, Proposal, Sampler, available_samplers, get_sampler, register_sampler

__all__ = [
    "AssetFetchError",
    "CollisionChecker",
    "CollisionReport",
    "ConfigError",
    "ContactSurface",
    "FitConfig",
    "FitResult",
    "FitStatus",
    "GeometryLoadError",
    "Grasp",
    "Gripper",
    "GripperDescriptionError",
    "ISFError",
    "ISFWarning",
    "InvalidInputError",
    "IterationRecord",
    "JointLimitError",
    "JointLimitViolation",
    "MeshNotFoundError",
    "ModelBuildError",
    "ObjectLoadError",
    "ObjectSurface",
    "Outcome",
    "PlanResult",
    "PlanStats",
    "Plane",
    "PluginLoadError",
    "Proposal",
    "QPStepError",
    "RegistrationError",
    "RepairConfig",
    "Sampler",
    "SamplerNotFound",
    "SurfaceSelectionError",
    "URDFReadError",
    "UnknownAssetError",
    "YCBNotFoundError",
    "__version__",
    "available_samplers",
    "fit",
    "fit_many",
    "get_sampler",
    "inspect_gripper",
    "load_gripper",
    "load_object",
    "open_object",
    "plan",
    "register_sampler",
]
