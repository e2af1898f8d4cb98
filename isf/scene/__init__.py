"""Scenes: plan on what depth cameras see (partial, noisy, unsegmented clouds of a cluttered table).

:func:`load_scene` reads depth images or point clouds with their cameras' intrinsics and poses
into a :class:`Scene`: the observed surface above the table (what ISF fits), the table (an
obstacle plane) and the unseen space behind the observations (an obstacle too). :func:`isf.plan`
takes a scene wherever it takes an object. See docs/tutorial-depth-camera.md for the frames.
"""

from .camera import CameraIntrinsics, camera_pose, parse_intrinsics
from .finger_depth import FingerDepth
from .loading import (
    ISOLATION_NEIGHBOURS,
    ISOLATION_RADIUS,
    NORMAL_NEIGHBOURS,
    SCENE_VOXEL,
    Scene,
    load_scene,
)
from .segments import SceneSegments, segment_surface
from .settle import NOISE_MARGIN, Settled, Settler, contact_allowance
from .table import TABLE_MARGIN, find_table
from .unseen import UnseenSpace, ViewDepth
from .views import SceneView

__all__ = [
    "CameraIntrinsics",
    "FingerDepth",
    "ISOLATION_NEIGHBOURS",
    "ISOLATION_RADIUS",
    "NOISE_MARGIN",
    "NORMAL_NEIGHBOURS",
    "SCENE_VOXEL",
    "Scene",
    "SceneSegments",
    "SceneView",
    "Settled",
    "Settler",
    "TABLE_MARGIN",
    "UnseenSpace",
    "ViewDepth",
    "camera_pose",
    "contact_allowance",
    "find_table",
    "load_scene",
    "parse_intrinsics",
    "segment_surface",
]
