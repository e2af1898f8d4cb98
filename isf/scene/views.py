"""One camera's observation: a depth image or a point cloud, the camera's intrinsics and pose.

:class:`SceneView` says what was observed and from where; :func:`observe` reads it into an
:class:`Observation`: the observed points in the scene frame and a *depth buffer*, the depth
image the camera saw (for a point cloud, the image its points make in the camera). The depth
buffer is what decides the unseen space (:mod:`isf.scene.unseen`).

Sources
    * a depth image: a 16-bit PNG, or an NPY / array of shape (H, W), depth along the optical
      axis; 0 or NaN is a pixel with no measurement. Needs ``intrinsics``. Its values are
      multiplied by ``depth_scale`` (default 0.001 for integer images, the millimetres of most
      depth cameras, and 1 for floating-point images, taken as metres);
    * a point cloud: PLY (without faces), PCD, XYZ/TXT, NPY or an (N, 3) / (N, 6) array, in the
      camera frame (what a camera driver writes; ``cloud_frame="scene"`` for a cloud already
      in the scene frame), metres times ``depth_scale`` (default 1). Without ``intrinsics``,
      the depth buffer is drawn in a virtual pinhole camera at the camera pose whose pixels are
      about as wide as the gaps between the points.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..exceptions import InvalidInputError, ObjectLoadError
from ..object.clouds import read_cloud
from .camera import CameraIntrinsics, camera_pose, parse_intrinsics

__all__ = ["Observation", "SceneView", "observe"]

_IMAGE_SUFFIXES = {".png"}
_MAX_BUFFER_PIXELS = 4_000_000  # the largest virtual depth buffer drawn for a cloud
_BUFFER_POINTS = 50_000  # points whose spacing sets a virtual buffer's pixel size
_PIXEL_PER_GAP = 1.2  # a virtual buffer's pixel width, in gaps between neighbouring points


@dataclass(frozen=True, eq=False)
class SceneView:
    """What one camera observed, and where the camera was.

    Attributes:
        source: a depth image (PNG/NPY path or (H, W) array) or a point cloud (file path or
            (N, 3)/(N, 6) array); see :mod:`isf.scene.views`.
        intrinsics: the camera's :class:`CameraIntrinsics` (or anything
            :func:`isf.scene.camera.parse_intrinsics` takes); required for a depth image.
        T_scene_camera: pose of the camera in the scene frame (4, 4), or a file / text that
            :func:`isf.scene.camera.camera_pose` reads; None: the scene frame is the camera's.
        depth_scale: metres per unit of the source; None: 0.001 for an integer depth image,
            else 1.
        cloud_frame: ``"camera"`` (default) or ``"scene"``: the frame a point cloud's
            coordinates are in (a depth image is always in the camera frame).
    """

    source: object
    intrinsics: object = None
    T_scene_camera: object = None
    depth_scale: float | None = None
    cloud_frame: str = "camera"


@dataclass(frozen=True, eq=False)
class Observation:
    """A view read into the scene frame.

    Attributes:
        points: observed points, scene frame, (M, 3), metres.
        normals: normals given by a cloud (scene frame, (M, 3)), or None.
        depth: the depth buffer (H, W), metres along the optical axis, 0 where nothing was seen.
        intrinsics: the camera of ``depth`` (its size set).
        T_scene_camera: the camera's pose in the scene frame, (4, 4).
        name: where the view came from.
    """

    points: np.ndarray
    normals: np.ndarray | None
    depth: np.ndarray
    intrinsics: CameraIntrinsics
    T_scene_camera: np.ndarray
    name: str = "scene"

    @property
    def camera_position(self) -> np.ndarray:
        """The camera's optical centre in the scene frame, (3,), metres."""
        return self.T_scene_camera[:3, 3]


def observe(view: SceneView) -> Observation:
    """Read a :class:`SceneView` into an :class:`Observation`.

    Raises:
        InvalidInputError: bad intrinsics, camera pose, depth scale or cloud frame, or a depth
            image without intrinsics.
        ObjectLoadError: the source cannot be read, holds no valid measurement, or a
            camera-frame cloud has points behind the camera.
    """
    T = np.eye(4) if view.T_scene_camera is None else camera_pose(view.T_scene_camera)
    if view.cloud_frame not in ("camera", "scene"):
        raise InvalidInputError(f"cloud_frame must be 'camera' or 'scene', got {view.cloud_frame!r}")
    intrinsics = None if view.intrinsics is None else parse_intrinsics(view.intrinsics)
    image, name = _depth_image(view.source)
    if image is not None:
        return _from_depth(image, name, intrinsics, T, view.depth_scale)
    points, normals, name = read_cloud(view.source)
    scale = _scale(view.depth_scale, 1.0)
    if not np.isfinite(points).all():
        keep = np.isfinite(points).all(axis=1)  # NaN rows: pixels with no return in organised clouds
        points, normals = points[keep], None if normals is None else normals[keep]
    if len(points) == 0:
        raise ObjectLoadError(f"scene {name} holds no finite points: pass a non-empty cloud")
    points = points * scale
    if view.cloud_frame == "scene":
        camera_points = (points - T[:3, 3]) @ T[:3, :3]
    else:
        camera_points = points
        points = points @ T[:3, :3].T + T[:3, 3]
        if normals is not None:
            normals = normals @ T[:3, :3].T
    if (camera_points[:, 2] <= 0).any():
        n = int((camera_points[:, 2] <= 0).sum())
        raise ObjectLoadError(
            f"scene {name}: {n} of {len(points)} points lie behind the camera (z <= 0 in the "
            "camera frame): give the camera pose T_scene_camera (--camera-pose), or cloud_frame="
            "'scene' (--cloud-frame scene) if the cloud is already in the scene frame")
    depth, intrinsics = _cloud_buffer(camera_points, intrinsics)
    return Observation(points, normals, depth, intrinsics, T, name)


def _scale(value, default: float) -> float:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(value) and value > 0):
        raise InvalidInputError(f"depth_scale must be a number of metres per unit > 0, got {value!r}")
    return float(value)


def _depth_image(source) -> tuple[np.ndarray | None, str]:
    """The source as a depth image (H, W) if it is one, else None; and its name."""
    if isinstance(source, np.ndarray):
        is_image = source.ndim == 2 and source.shape[1] not in (3, 6)
        return (source if is_image else None), "array"
    if not isinstance(source, (str, os.PathLike)):
        return None, "scene"
    path = Path(source)
    suffix = path.suffix.lower()
    if suffix in _IMAGE_SUFFIXES:
        if not path.is_file():
            raise ObjectLoadError(f"depth image {path} does not exist: check the path", source=path)
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as image:
                array = np.array(image)
        except (OSError, UnidentifiedImageError) as err:
            raise ObjectLoadError(f"cannot read {path} as a PNG depth image ({err}): save the "
                                  "depth as a 16-bit single-channel PNG", source=path) from None
        if array.ndim != 2:
            raise ObjectLoadError(f"{path} has {array.shape[2]} channels: a depth image has one "
                                  "(16-bit grey, values in depth_scale units)", source=path)
        return array, path.name
    if suffix == ".npy" and path.is_file():
        try:
            array = np.load(path, allow_pickle=False, mmap_mode="r")
        except (ValueError, OSError):
            return None, path.name  # the cloud reader reports it
        if array.ndim == 2 and array.shape[1] not in (3, 6):
            return np.asarray(array), path.name
    return None, path.name


def _from_depth(image: np.ndarray, name: str, intrinsics: CameraIntrinsics | None,
                T: np.ndarray, depth_scale) -> Observation:
    if intrinsics is None:
        raise InvalidInputError(f"depth image {name} needs the camera intrinsics fx, fy, cx, cy "
                                "(--intrinsics fx,fy,cx,cy)")
    if not np.issubdtype(image.dtype, np.number) or image.dtype == bool:
        raise ObjectLoadError(f"depth image {name} has dtype {image.dtype}: pass depths as numbers")
    integer = np.issubdtype(image.dtype, np.integer)
    depth = image.astype(np.float64) * _scale(depth_scale, 0.001 if integer else 1.0)
    depth[~np.isfinite(depth) | (depth < 0)] = 0.0
    h, w = depth.shape
    if intrinsics.width and (intrinsics.width, intrinsics.height) != (w, h):
        raise InvalidInputError(f"depth image {name} is {w} x {h} pixels but the intrinsics say "
                                f"{intrinsics.width} x {intrinsics.height}: pass the intrinsics of "
                                "this image")
    intrinsics = intrinsics.with_size(w, h)
    points, _ = intrinsics.back_project(depth)
    if len(points) == 0:
        raise ObjectLoadError(f"depth image {name} has no valid pixel (all 0 or NaN): the scene "
                              "is empty")
    return Observation(points @ T[:3, :3].T + T[:3, 3], None, depth, intrinsics, T, name)


def _cloud_buffer(points: np.ndarray,
                  intrinsics: CameraIntrinsics | None) -> tuple[np.ndarray, CameraIntrinsics]:
    """The depth image camera-frame ``points`` (M, 3) make: in ``intrinsics`` when given (their
    size, or one covering the points), else in a virtual camera whose pixels are about as wide
    as the gaps between neighbouring points. Each pixel holds the nearest point's depth."""
    if intrinsics is None:
        pick = points[:: max(1, len(points) // _BUFFER_POINTS)]
        gap = float(np.median(cKDTree(pick).query(pick, k=2)[0][:, 1]))
        z = float(np.median(pick[:, 2]))
        gap *= max(1.0, len(points) / len(pick)) ** -0.5  # a subsample's gaps are wider
        f = z / max(_PIXEL_PER_GAP * gap, 1e-6)
        intrinsics = CameraIntrinsics(f, f, 0.0, 0.0)
        u, v, _ = intrinsics.project(points)
        while (np.ptp(u) + 3) * (np.ptp(v) + 3) > _MAX_BUFFER_PIXELS:
            f *= 0.7
            intrinsics = CameraIntrinsics(f, f, 0.0, 0.0)
            u, v, _ = intrinsics.project(points)
        intrinsics = CameraIntrinsics(f, f, 1.0 - np.floor(u.min()), 1.0 - np.floor(v.min()))
    if not intrinsics.width:
        u, v, _ = intrinsics.project(points)
        width, height = int(np.ceil(u.max())) + 2, int(np.ceil(v.max())) + 2
        if u.min() < -0.5 or v.min() < -0.5 or width * height > _MAX_BUFFER_PIXELS:
            raise InvalidInputError("the cloud's points fall outside the image of the given "
                                    "intrinsics: pass their width and height, or no intrinsics")
        intrinsics = intrinsics.with_size(width, height)
    u, v, z = intrinsics.project(points)
    col, row = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    inside = (col >= 0) & (col < intrinsics.width) & (row >= 0) & (row < intrinsics.height)
    depth = np.full(intrinsics.height * intrinsics.width, np.inf)
    np.minimum.at(depth, row[inside] * intrinsics.width + col[inside], z[inside])
    depth[np.isinf(depth)] = 0.0
    return depth.reshape(intrinsics.height, intrinsics.width), intrinsics
