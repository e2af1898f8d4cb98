"""Pinhole cameras: intrinsics, the camera pose ``T_scene_camera``, projection and back-projection.

Frames
    *camera*: origin at the optical centre, x to the right of the image, y down the image, z
    forward along the optical axis (the convention of depth images, OpenCV and ROS optical
    frames). A pixel ``(u, v)`` (column, row) with depth ``z`` is the camera point
    ``((u - cx) z / fx, (v - cy) z / fy, z)``, where pixel centres lie at integer coordinates.

    *scene*: the frame the grasps are planned in. ``T_scene_camera`` (4, 4) is the pose of the
    camera in it; without one the scene frame is the camera frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InvalidInputError

__all__ = ["CameraIntrinsics", "camera_pose", "parse_intrinsics"]

_RIGID_TOLERANCE = 1e-6


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole camera's intrinsics, in pixels.

    Attributes:
        fx, fy: focal lengths, pixels (> 0).
        cx, cy: principal point (column, row), pixels.
        width, height: image size, pixels; 0 when not known (a depth image gives its own).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 0
    height: int = 0

    def __post_init__(self) -> None:
        values = {}
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not np.isfinite(value):
                raise InvalidInputError(f"camera intrinsics: {name} must be a finite number of "
                                        f"pixels, got {value!r}")
            values[name] = float(value)
        if values["fx"] <= 0 or values["fy"] <= 0:
            raise InvalidInputError(f"camera intrinsics: fx and fy must be > 0 pixels, got "
                                    f"fx={values['fx']}, fy={values['fy']}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise InvalidInputError(f"camera intrinsics: {name} must be a whole number of "
                                        f"pixels >= 0, got {value!r}")
            values[name] = int(value)
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def with_size(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera with the image size ``width`` x ``height`` pixels."""
        return CameraIntrinsics(self.fx, self.fy, self.cx, self.cy, int(width), int(height))

    def back_project(self, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points of the valid pixels of a depth image.

        Args:
            depth: (H, W) metres along the optical axis; 0, negative or NaN = no measurement.

        Returns:
            (points (M, 3) camera frame, metres; flat pixel indices (M,) into ``depth``).
        """
        h, w = depth.shape
        flat = np.flatnonzero(np.isfinite(depth.ravel()) & (depth.ravel() > 0))
        z = depth.ravel()[flat]
        v, u = np.divmod(flat, w)
        points = np.column_stack([(u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z])
        return points, flat

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates of camera-frame points.

        Args:
            points: (M, 3) camera frame, metres.

        Returns:
            (column u (M,), row v (M,), depth z (M,)), pixels and metres; u and v are NaN where
            ``z <= 0`` (behind the camera).
        """
        z = points[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(z > 0, 1.0 / z, np.nan)
        return self.fx * points[:, 0] * inv + self.cx, self.fy * points[:, 1] * inv + self.cy, z


def parse_intrinsics(value) -> CameraIntrinsics:
    """Intrinsics from a :class:`CameraIntrinsics`, a mapping with keys fx, fy, cx, cy (and
    optionally width, height), a sequence ``(fx, fy, cx, cy[, width, height])`` or the text
    ``"fx,fy,cx,cy"`` (the CLI's ``--intrinsics``).

    Raises:
        InvalidInputError: anything else, or values out of range.
    """
    if isinstance(value, CameraIntrinsics):
        return value
    hint = "pass fx,fy,cx,cy in pixels, e.g. 307.5,307.5,159.5,119.5"
    if isinstance(value, str):
        try:
            value = [float(word) for word in value.replace(",", " ").split()]
        except ValueError:
            raise InvalidInputError(f"camera intrinsics {value!r} are not numbers: {hint}") from None
    if isinstance(value, dict):
        unknown = set(value) - {"fx", "fy", "cx", "cy", "width", "height"}
        if unknown or not {"fx", "fy", "cx", "cy"} <= set(value):
            raise InvalidInputError(f"camera intrinsics {value!r} need the keys fx, fy, cx, cy "
                                    "(and optionally width, height)")
        return CameraIntrinsics(**value)
    if isinstance(value, (list, tuple, np.ndarray)) and len(value) in (4, 6):
        fx, fy, cx, cy, *size = value
        if size:
            size = [int(s) if float(s).is_integer() else s for s in size]
        return CameraIntrinsics(fx, fy, cx, cy, *size)
    raise InvalidInputError(f"camera intrinsics {value!r} are not understood: {hint}")


def camera_pose(value) -> np.ndarray:
    """``T_scene_camera`` (4, 4) from an array, a .npy or text file holding 16 numbers (4 rows
    of 4), or the text of 16 comma-separated numbers (row by row).

    Raises:
        InvalidInputError: not 16 finite numbers, or not a rigid transform (a rotation
            orthonormal to 1e-6 with determinant +1, last row ``0 0 0 1``).
    """
    source = value
    if isinstance(value, (str, os.PathLike)) and Path(value).is_file():
        path = Path(value)
        try:
            value = np.load(path, allow_pickle=False) if path.suffix == ".npy" else \
                np.loadtxt(path, delimiter=None if "," not in path.read_text() else ",")
        except (OSError, ValueError) as err:
            raise InvalidInputError(f"camera pose file {path} cannot be read ({err}): write the "
                                    "4x4 T_scene_camera as 4 lines of 4 numbers or as .npy") from None
    elif isinstance(value, str):
        try:
            value = [float(word) for word in value.replace(",", " ").split()]
        except ValueError:
            raise InvalidInputError(f"camera pose {value!r} is neither a file nor 16 numbers: pass "
                                    "a .npy/text file or 16 comma-separated numbers, row by row") from None
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(f"camera pose {source!r} is not a 4x4 matrix") from None
    if T.size != 16:
        raise InvalidInputError(f"camera pose {source!r} has {T.size} numbers: T_scene_camera "
                                "needs 16 (a 4x4 matrix, row by row)")
    T = T.reshape(4, 4)
    if not np.isfinite(T).all():
        raise InvalidInputError("camera pose T_scene_camera has non-finite entries: pass a rigid 4x4")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > _RIGID_TOLERANCE or np.linalg.det(R) < 0 \
            or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12:
        raise InvalidInputError("camera pose T_scene_camera is not rigid (its rotation is not "
                                "orthonormal with determinant +1, or its last row is not 0 0 0 1): "
                                "pass the camera's pose in the scene frame, translation in metres")
    return T
