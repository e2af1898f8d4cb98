"""The unseen space of a scene: what lies behind the observed surfaces along the cameras' rays.

A camera that measured depth ``d`` at a pixel saw empty space in front of ``d`` and nothing
behind it: the space behind is occupied or unknown, and a gripper must not enter it (it could
be the back of an object the camera did not see). A point ``p`` of the scene frame is behind a
camera's observations when, in that camera's frame, it projects into the image at a pixel
whose *occlusion depth* ``D`` is smaller than its own depth ``z``; ``z - D`` (metres along the
optical axis) is how far behind it lies. With several cameras, a point is unseen only when it
lies behind the observations of every camera that has an opinion about it (one camera that saw
through it frees it), and its depth behind is the smallest over those cameras.

The occlusion depth of a pixel is the largest measured depth among it and its 8 neighbours:

* a pixel without a measurement (0 in the depth image: a grazing angle, a dark surface) takes
  its neighbours' depth, so a lone missing pixel in a surface does not open a hole in it;
* at the silhouette of an object the background's depth wins, so a finger that touches an
  object's visible outline is not taken to be behind it (a one-pixel allowance: 1 mm at 0.5 m
  for a 320 x 240 image with a 60 degree field of view);
* a pixel whose neighbourhood holds no measurement constrains nothing, nor does a point outside
  every camera's image or behind every camera: isf does not guess what no camera saw there
  (the table plane, an obstacle of its own, still bounds the space from below).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter

from .camera import CameraIntrinsics

__all__ = ["UnseenSpace", "ViewDepth"]


@dataclass(frozen=True, eq=False)
class ViewDepth:
    """One camera's occlusion depths.

    Attributes:
        occlusion: (H, W) occlusion depth per pixel, metres; inf where nothing constrains.
        intrinsics: the camera.
        T_camera_scene: pose of the scene frame in the camera frame, (4, 4).
    """

    occlusion: np.ndarray
    intrinsics: CameraIntrinsics
    T_camera_scene: np.ndarray

    @classmethod
    def from_depth(cls, depth: np.ndarray, intrinsics: CameraIntrinsics,
                   T_scene_camera: np.ndarray) -> ViewDepth:
        """From a depth image (H, W) (metres, 0 = no measurement) of a camera at
        ``T_scene_camera`` (4, 4)."""
        measured = np.where(depth > 0, depth, -np.inf)
        occlusion = maximum_filter(measured, size=3, mode="constant", cval=-np.inf)
        occlusion[np.isneginf(occlusion)] = np.inf
        return cls(occlusion, intrinsics, np.linalg.inv(T_scene_camera))

    @property
    def camera_position(self) -> np.ndarray:
        """The camera's optical centre in the scene frame, (3,), metres."""
        return np.linalg.inv(self.T_camera_scene)[:3, 3]

    def depth_behind(self, points: np.ndarray) -> np.ndarray:
        """How far behind this camera's observations each point lies, metres along the optical
        axis: > 0 behind, <= 0 in front; NaN where the camera has no opinion.

        Args:
            points: (M, 3) scene frame, metres.
        """
        R, t = self.T_camera_scene[:3, :3], self.T_camera_scene[:3, 3]
        u, v, z = self.intrinsics.project(points @ R.T + t)
        h, w = self.occlusion.shape
        with np.errstate(invalid="ignore"):
            col, row = np.rint(u), np.rint(v)
            inside = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        behind = np.full(len(points), np.nan)
        occlusion = self.occlusion[row[inside].astype(np.int64), col[inside].astype(np.int64)]
        behind[inside] = np.where(np.isinf(occlusion), np.nan, z[inside] - occlusion)
        return behind


@dataclass(frozen=True, eq=False)
class UnseenSpace:
    """The space behind a scene's observations, over all its cameras (see the module docs).

    Attributes:
        views: one :class:`ViewDepth` per camera.
        name: the name collision reports give it.
    """

    views: tuple[ViewDepth, ...]
    name: str = "unseen"

    def depth_inside(self, points: np.ndarray) -> np.ndarray:
        """How far inside the unseen space each point lies, metres (> 0 inside; 0 for a point
        any camera saw in front of its observations or that no camera has an opinion about).

        Args:
            points: (M, 3) scene frame, metres.

        Returns:
            (M,) metres.
        """
        depth = np.full(len(points), np.inf)
        for view in self.views:
            behind = view.depth_behind(points)
            known = ~np.isnan(behind)
            depth[known] = np.minimum(depth[known], behind[known])
        depth[np.isinf(depth)] = 0.0
        return np.maximum(depth, 0.0)

    def way_out(self, points: np.ndarray) -> np.ndarray:
        """For each point, the unit direction back along the line of sight of the camera it
        lies least deep behind (towards that camera): the way out of the unseen space.

        Args:
            points: (M, 3) scene frame, metres.

        Returns:
            (M, 3) unit vectors.
        """
        best = np.full(len(points), np.inf)
        out = np.zeros((len(points), 3))
        for view in self.views:
            behind = view.depth_behind(points)
            closer = ~np.isnan(behind) & (behind < best)
            towards = view.camera_position - points[closer]
            out[closer] = towards / np.linalg.norm(towards, axis=1, keepdims=True)
            best[closer] = behind[closer]
        return out
