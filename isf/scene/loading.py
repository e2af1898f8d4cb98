"""Load what one or more cameras saw into a :class:`Scene` that :func:`isf.plan` plans on.

:func:`load_scene` reads each view (:mod:`isf.scene.views`) into the scene frame and then:

1. finds or takes the table (:mod:`isf.scene.table`): an obstacle plane for the collision
   checks, and the points within :data:`~isf.scene.table.TABLE_MARGIN` above it (and all below
   it) leave the surface that ISF fits;
2. thins the rest to one point per ``voxel_size`` voxel (their mean), so a scene of millions of
   points costs no more than its resolution is worth, and drops the *isolated* points: those with
   fewer than :data:`ISOLATION_NEIGHBOURS` others within :data:`ISOLATION_RADIUS` (or 4 voxels,
   if larger). They are not surfaces but the sensor's strays: the far table's noisiest
   measurements rising past the table margin, flying pixels between an object and its
   background. Left in, each would be a cluster of its own for the samples to spread over (on a
   table with one small object left, most of a plan's samples), with a normal fitted to
   neighbours centimetres away. The unseen space behind them stays;
3. estimates normals by PCA over each point's ``NORMAL_NEIGHBOURS`` (16) nearest neighbours,
   moves each point onto its local plane (smoothing the depth noise across the surface, as the
   paper smoothed its stereo clouds) and turns each normal towards the camera that saw the point
   (every point a camera saw faces it); the neighbours' scatter about those planes (their RMS
   distance, the median over the points) is the scene's ``Scene.noise``, which sets how far
   a settled grasp stays out of the observed surface (:mod:`isf.scene.settle`);
4. splits the surface into smooth, convex pieces (:mod:`isf.scene.segments`), which the planner
   uses to rank down grasps resting on two objects;
5. keeps each camera's depth buffer as the scene's unseen space (:mod:`isf.scene.unseen`),
   which the collision checks treat as an obstacle.

Frames: everything of a :class:`Scene` is in the *scene* frame: the frame of the camera poses
``T_scene_camera`` (the first camera's frame when no pose is given). The planner's "object
frame" is the scene frame: a grasp's ``T_object_gripper`` is its pose in the scene.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..collision.checker import Plane
from ..exceptions import InvalidInputError, ObjectLoadError
from ..object.clouds import estimate_normals, voxel_downsample
from ..object.surface import ObjectSurface
from ..search.voxel_grid import voxel_labels
from .segments import SceneSegments
from .table import TABLE_MARGIN, resolve_table
from .unseen import UnseenSpace, ViewDepth
from .views import SceneView, observe

__all__ = ["ISOLATION_NEIGHBOURS", "ISOLATION_RADIUS", "NORMAL_NEIGHBOURS", "SCENE_VOXEL", "Scene",
           "load_scene"]

logger = logging.getLogger(__name__)

SCENE_VOXEL = 0.002
"""Default voxel size a scene's surface is thinned to, metres."""

NORMAL_NEIGHBOURS = 16
"""Neighbours (the point included) whose principal axes give a scene point's normal."""

ISOLATION_RADIUS = 0.015
"""Radius of the neighbourhood that decides whether a thinned surface point is isolated, metres
(at least 4 voxels)."""

ISOLATION_NEIGHBOURS = 5
"""Other thinned surface points a point needs within :data:`ISOLATION_RADIUS` to be kept."""

_MIN_POINTS = 10


@dataclass(frozen=True, eq=False)
class Scene:
    """What the cameras saw, ready to plan on (every array in the scene frame, metres).

    Attributes:
        surface: the observed surface above the table, thinned, smoothed, with normals facing
            the cameras: what ISF fits and the collision checks test against.
        table: the support plane (an obstacle), or None.
        unseen: the space behind the observations (an obstacle; :mod:`isf.scene.unseen`).
        segments: the surface's smooth, convex pieces (:mod:`isf.scene.segments`).
        T_scene_camera: each camera's pose, (C, 4, 4).
        observed: points the cameras measured, before the table was removed and the rest thinned.
        name: where the scene came from.
        noise: the surface's depth noise, metres: the median over its points of the RMS
            distance of a point's neighbours from its local plane (step 3 of
            :func:`load_scene`), before the smoothing.
        scatter: (N,) each surface point's local scatter, metres: the RMS distance of its
            neighbours from its local plane, before the smoothing (the sensor noise on a smooth
            face, more where the neighbourhood bends over an edge; :mod:`isf.scene.finger_depth`).
            None for a scene built without it.
    """

    surface: ObjectSurface
    table: Plane | None
    unseen: UnseenSpace
    segments: SceneSegments
    T_scene_camera: np.ndarray
    observed: int
    name: str = "scene"
    noise: float = 0.0
    scatter: np.ndarray | None = None

    @property
    def obstacles(self) -> tuple[Plane, ...]:
        """The scene's obstacle planes (the table, if any)."""
        return () if self.table is None else (self.table,)

    def __repr__(self) -> str:
        table = "none" if self.table is None else (
            f"normal {np.round(self.table.normal, 3).tolist()}, offset {self.table.offset:.4f} m")
        return (f"Scene({self.name!r}: {self.observed} points observed by "
                f"{len(self.T_scene_camera)} camera(s), {self.surface.n_points} above the table "
                f"at {self.surface.spacing * 1e3:.1f} mm, {self.segments.count} pieces; table {table})")


def load_scene(
    source,
    *,
    intrinsics=None,
    T_scene_camera=None,
    depth_scale: float | None = None,
    cloud_frame: str = "camera",
    table: float | str | Plane | None = None,
    voxel_size: float = SCENE_VOXEL,
    name: str | None = None,
) -> Scene:
    """Load a camera's depth image or point cloud (or several cameras' views) as a scene.

    Args:
        source: a depth image or point cloud (a path or an array; see
            :mod:`isf.scene.views`), a :class:`SceneView`, or a sequence of views (one per
            camera). With views, the keywords below up to ``cloud_frame`` must be left unset.
        intrinsics: the camera's intrinsics (:class:`CameraIntrinsics`, a mapping, a sequence
            or "fx,fy,cx,cy" pixels); required for a depth image.
        T_scene_camera: the camera's pose in the scene frame (4, 4), a .npy/text file or 16
            numbers; None: the scene frame is the camera frame (x right, y down, z forward).
        depth_scale: metres per unit of the source; None: 0.001 for integer depth images, else 1.
        cloud_frame: ``"camera"`` (default) or ``"scene"``: the frame of a point cloud's
            coordinates.
        table: None (no table), a height ``z`` of the scene frame (the plane ``z = const``, free
            above: use it when the scene frame's z axis points up), a
            :class:`~isf.collision.checker.Plane`, or ``"auto"`` (the dominant plane, by RANSAC).
        voxel_size: the surface is thinned to one point per voxel of this size, metres.
        name: the scene's name (default: the first view's file name).

    Returns:
        the :class:`Scene`.

    Raises:
        InvalidInputError: bad intrinsics, camera pose, depth scale, table or voxel size; a
            depth image without intrinsics.
        ObjectLoadError: a source cannot be read or holds no valid measurement; no table
            plane is found; no point lies above the table.
    """
    views = _views(source, intrinsics=intrinsics, T_scene_camera=T_scene_camera,
                   depth_scale=depth_scale, cloud_frame=cloud_frame)
    if isinstance(voxel_size, bool) or not isinstance(voxel_size, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(voxel_size) and voxel_size > 0):
        raise InvalidInputError(f"voxel_size must be a spacing > 0 in metres, got {voxel_size!r}")
    observations = [observe(view) for view in views]
    label = name if name is not None else observations[0].name
    points = np.concatenate([o.points for o in observations])
    camera_of = np.concatenate([np.full(len(o.points), k) for k, o in enumerate(observations)])
    cameras = np.array([o.camera_position for o in observations])
    given = None if any(o.normals is None for o in observations) else \
        np.concatenate([o.normals for o in observations])
    plane = resolve_table(table, points, cameras)
    if plane is not None:
        above = plane.height(points) > TABLE_MARGIN
        if not above.any():
            raise ObjectLoadError(
                f"scene {label}: none of its {len(points)} points lies more than "
                f"{TABLE_MARGIN * 1e3:.0f} mm above the table: check the table height and the "
                "camera pose, or plan without --table")
        points, camera_of = points[above], camera_of[above]
        given = None if given is None else given[above]
    surface, scatter = _surface(points, given, camera_of, cameras, float(voxel_size), label)
    unseen = UnseenSpace(tuple(ViewDepth.from_depth(o.depth, o.intrinsics, o.T_scene_camera)
                               for o in observations))
    scene = Scene(surface, plane, unseen, SceneSegments.of(surface.points, surface.normals,
                                                           surface.spacing),
                  np.array([o.T_scene_camera for o in observations]),
                  sum(len(o.points) for o in observations), label, float(np.median(scatter)),
                  scatter)
    logger.info("%r", scene)
    return scene


def _views(source, **single) -> list[SceneView]:
    """The views of :func:`load_scene`'s ``source``; the keywords describe a single source."""
    if isinstance(source, SceneView) or (
            isinstance(source, Sequence) and not isinstance(source, str) and source
            and all(isinstance(v, SceneView) for v in source)):
        changed = [key for key, value in single.items()
                   if value is not None and not (key == "cloud_frame" and value == "camera")]
        if changed:
            raise InvalidInputError(f"load_scene: {', '.join(changed)} belong in each SceneView "
                                    "when views are given")
        return [source] if isinstance(source, SceneView) else list(source)
    if isinstance(source, Sequence) and not isinstance(source, str) and not source:
        raise ObjectLoadError("load_scene got no views: the scene is empty")
    return [SceneView(source, **single)]


def _surface(points: np.ndarray, given: np.ndarray | None, camera_of: np.ndarray,
             cameras: np.ndarray, voxel: float, label: str) -> tuple[ObjectSurface, np.ndarray]:
    """Thin, smooth and give camera-facing normals to the points above the table; also each
    point's local scatter (``Scene.scatter``; its median is ``Scene.noise``), (N,) metres."""
    labels, n_vox = voxel_labels(points, voxel)
    _, first = np.unique(labels, return_index=True)
    camera_of = camera_of[first]
    points, normals = voxel_downsample(points, given, labels, n_vox)
    kept = _not_isolated(points, max(ISOLATION_RADIUS, 4 * voxel))
    if not kept.all():
        logger.info("scene %s: %d isolated points of %d dropped", label, int((~kept).sum()),
                    len(points))
        points, camera_of = points[kept], camera_of[kept]
        normals = None if normals is None else normals[kept]
    if len(points) < _MIN_POINTS:
        raise ObjectLoadError(f"scene {label} has {len(points)} surface points above the table "
                              f"at {voxel * 1e3:.1f} mm voxels, fewer than {_MIN_POINTS}: nothing "
                              "to grasp")
    k = min(NORMAL_NEIGHBOURS, len(points))
    dist, neighbours = cKDTree(points).query(points, k=k, workers=1)
    spacing = float(np.median(dist[:, 1]))
    if normals is None:
        normals = estimate_normals(points, neighbours)
    centres = points[neighbours].mean(axis=1)
    scatter = np.einsum("ikj,ij->ik", points[neighbours] - centres[:, None], normals)
    local_scatter = np.sqrt(np.mean(scatter ** 2, axis=1))
    if given is None:
        points = points - np.einsum("ij,ij->i", points - centres, normals)[:, None] * normals
    towards = cameras[camera_of] - points
    normals = np.where((np.einsum("ij,ij->i", normals, towards) < 0)[:, None], -normals, normals)
    return ObjectSurface(points=points, normals=normals, spacing=max(spacing, voxel), name=label,
                         viewpoints=cameras), local_scatter


def _not_isolated(points: np.ndarray, radius: float) -> np.ndarray:
    """(N,) bool: the points (N, 3) with at least :data:`ISOLATION_NEIGHBOURS` others within
    ``radius`` metres."""
    counts = cKDTree(points).query_ball_point(points, radius, return_length=True, workers=1)
    return np.asarray(counts) > ISOLATION_NEIGHBOURS
