"""Ground-truth judging of a grasp in a simulated scene, independent of isf's collision checker.

A benchmark module (used by ``bench/bench_scenes.py`` and ``tests/test_scene_judge.py``); it
takes from isf only the gripper's link poses (``Gripper.link_poses``, Pinocchio's forward
kinematics), its collision meshes and its tagged contact points (``Gripper.contact_points``).
Every distance is measured with Open3D's ``RaycastingScene`` (exact point-to-triangle distances
and ray-parity occupancy) on the full meshes: the scene's ground-truth objects (watertight) and
the gripper's collision meshes.

A grasp ``(T_scene_gripper, q)`` passes when

* no penetration is deeper than ``PENETRATION_TOLERANCE`` (2 mm): into any object, measured both
  ways on surface samples ``SAMPLE_SPACING`` apart (the deepest gripper point inside an object,
  as its distance to the object's surface, and the deepest object point inside a gripper mesh,
  as its distance to that mesh's surface), or below the table (the lowest gripper vertex); and
* the contact surfaces touch exactly one object: every tagged contact surface has a point within
  ``CONTACT_TOLERANCE`` (2 mm) of that object, and no contact point is that close to another one.
  Touching the table is allowed.

Frames: ``scene`` (z up, table top at ``Scene.table_height``), the gripper's root link
(``T_scene_gripper`` places it), each link (``Gripper.link_poses`` gives ``T_gripper_link``) and
each object's mesh frame (``SceneObject.T_scene_object``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

import _common

#: Deepest penetration a passing grasp may have, metres.
PENETRATION_TOLERANCE = 0.002
#: Distance within which a contact point touches an object, metres.
CONTACT_TOLERANCE = 0.002
#: Spacing of the surface samples that detect penetration, metres.
SAMPLE_SPACING = 0.0015
#: Distance up to which the gap of a contact surface to the objects is measured, metres.
GAP_RANGE = 0.02
#: What the deepest penetration of a grasp that penetrates only the table is into.
TABLE = "table"


@dataclass(frozen=True)
class Judgement:
    """The verdict on one grasp.

    Attributes:
        passed: collision-free within tolerance and held by exactly one object.
        grasped: the single object every contact surface touches (None if there is none).
        penetration: the deepest penetration into any object or the table, metres (0 if none).
        obstacle: what that penetration is into: an object name, :data:`TABLE` or None.
        link: the gripper link that penetrates deepest, or None.
        deepest_point: scene-frame point on the obstacle's surface nearest to the deepest
            penetration, (3,) metres, or None.
        touched: for every contact surface, the objects within ``CONTACT_TOLERANCE``.
        gaps: for every contact surface, its points' smallest distance to any object, metres
            (inf when no object is within ``GAP_RANGE``).
        reason: ``"ok"`` or why the grasp failed: ``"penetration"``, ``"table"``,
            ``"no contact"`` (a surface touches nothing) or ``"two objects"``.
    """

    passed: bool
    grasped: str | None
    penetration: float
    obstacle: str | None
    link: str | None
    deepest_point: np.ndarray | None
    touched: dict[str, tuple[str, ...]]
    gaps: dict[str, float]
    reason: str

    def describe(self) -> str:
        """One line: the verdict, the penetration and the touched objects."""
        contacts = "; ".join(f"{s}: {', '.join(o) or 'nothing'} (gap {self.gaps[s] * 1e3:.1f} mm)"
                             for s, o in self.touched.items())
        where = f" of {self.link} into {self.obstacle}" if self.obstacle else ""
        return (f"{self.reason}: penetration {self.penetration * 1e3:.1f} mm{where}; "
                f"contacts {contacts}")


class MeshQuery:
    """Distances and occupancy for one watertight mesh in its own frame (Open3D), with surface
    samples ``spacing`` apart (its vertices included)."""

    def __init__(self, mesh: trimesh.Trimesh, spacing: float = SAMPLE_SPACING):
        o3d = _common.import_open3d()
        self._o3d = o3d
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                                 o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
        self.low, self.high = mesh.bounds
        self.centre = (self.low + self.high) / 2
        self.radius = float(np.linalg.norm(self.high - self.low) / 2)
        count = max(16, int(np.ceil(mesh.area / spacing**2)))
        sampled, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
        self.samples = np.concatenate([np.asarray(mesh.vertices), sampled])

    def _tensor(self, points: np.ndarray):
        return self._o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32))

    def near(self, points: np.ndarray, margin: float) -> np.ndarray:
        """Mask of ``points`` (N, 3) inside the bounding box grown by ``margin``."""
        return np.all((points >= self.low - margin) & (points <= self.high + margin), axis=1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance of ``points`` (N, 3) to the surface, metres."""
        if len(points) == 0:
            return np.zeros(0)
        return self.scene.compute_distance(self._tensor(points)).numpy().astype(float)

    def deepest_inside(self, points: np.ndarray) -> tuple[float, int]:
        """The largest distance to the surface among ``points`` inside the mesh and its index
        (0 and -1 when none is inside)."""
        candidates = np.flatnonzero(self.near(points, 0.0))
        if len(candidates) == 0:
            return 0.0, -1
        occupied = self.scene.compute_occupancy(self._tensor(points[candidates]),
                                                nsamples=3).numpy() > 0.5
        inside = candidates[occupied]
        if len(inside) == 0:
            return 0.0, -1
        depth = self.distance(points[inside])
        k = int(np.argmax(depth))
        return float(depth[k]), int(inside[k])

    def closest_point(self, point: np.ndarray) -> np.ndarray:
        """The surface point nearest to ``point`` (3,)."""
        found = self.scene.compute_closest_points(self._tensor(point[None]))
        return found["points"].numpy()[0].astype(float)


@functools.cache
def _mesh_query(mesh: trimesh.Trimesh) -> MeshQuery:
    """One :class:`MeshQuery` per mesh object (scenes share their catalogue's meshes)."""
    return MeshQuery(mesh)


@functools.cache
def _gripper_queries(gripper) -> tuple[tuple[str, MeshQuery, np.ndarray], ...]:
    """``(link, query, vertices)`` of every collision mesh of ``gripper``, in its link frame."""
    out = []
    for geometry in gripper.geometries:
        mesh = trimesh.Trimesh(geometry.vertices, geometry.faces, process=True)
        out.append((geometry.link, MeshQuery(mesh), np.asarray(geometry.vertices, float)))
    return tuple(out)


def _apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


class Judge:
    """Judges grasps of ``gripper`` against the ground truth of ``scene``.

    Args:
        gripper: an ``isf.Gripper`` with collision geometry and tagged contact surfaces.
        scene: the ground truth (``scene_sim.Scene`` or any object with ``objects`` having
            ``name``, ``mesh``, ``T_scene_object``, and ``table_height``).
    """

    def __init__(self, gripper, scene):
        if not gripper.geometries:
            raise ValueError(f"gripper {gripper.name!r} has no collision geometry to judge")
        self.gripper, self.scene = gripper, scene
        self._objects = []
        for obj in scene.objects:
            query = _mesh_query(obj.mesh)
            T = np.asarray(obj.T_scene_object, float)
            samples = _apply(T, query.samples)
            self._objects.append((obj.name, query, T, np.linalg.inv(T), cKDTree(samples),
                                  _apply(T, query.centre)))

    def __call__(self, T_scene_gripper: np.ndarray, q: np.ndarray) -> Judgement:
        """Judge the grasp: the gripper root at ``T_scene_gripper`` (4, 4), joints ``q``."""
        T_scene_gripper = np.asarray(T_scene_gripper, float)
        poses = self.gripper.link_poses(np.asarray(q, float))
        worst = (0.0, None, None, None)  # depth, obstacle, link, point (scene frame)
        for link, query, vertices in _gripper_queries(self.gripper):
            T_scene_link = T_scene_gripper @ poses[link]
            lowest = float(_apply(T_scene_link, vertices)[:, 2].min())
            below = self.scene.table_height - lowest
            if below > worst[0]:
                worst = (below, TABLE, link, None)
            T_link_scene = np.linalg.inv(T_scene_link)
            gripper_points = _apply(T_scene_link, query.samples)
            centre = _apply(T_scene_link, query.centre)
            for name, obj, T_scene_object, T_object_scene, tree, obj_centre in self._objects:
                if np.linalg.norm(centre - obj_centre) > query.radius + obj.radius:
                    continue
                # gripper points inside the object
                local = _apply(T_object_scene, gripper_points)
                depth, k = obj.deepest_inside(local)
                if depth > worst[0]:
                    worst = (depth, name, link,
                             _apply(T_scene_object, obj.closest_point(local[k])))
                # object points inside the gripper mesh
                nearby = tree.query_ball_point(centre, query.radius)
                if nearby:
                    points = tree.data[nearby]
                    depth, k = query.deepest_inside(_apply(T_link_scene, points))
                    if depth > worst[0]:
                        worst = (depth, name, link, points[k].copy())
        touched, gaps = self._touched(T_scene_gripper, q)
        return self._verdict(worst, touched, gaps)

    def _touched(self, T_scene_gripper: np.ndarray, q: np.ndarray
                 ) -> tuple[dict[str, tuple[str, ...]], dict[str, float]]:
        """For every contact surface, the objects one of its points is within
        ``CONTACT_TOLERANCE`` of, and the surface's smallest distance to any object."""
        points, _ = self.gripper.contact_points(np.asarray(q, float))
        points = _apply(T_scene_gripper, points)
        surface = self.gripper.point_surface
        names = [s.name for s in self.gripper.surfaces]
        touched = {s: [] for s in names}
        gaps = dict.fromkeys(names, np.inf)
        for name, obj, _, T_object_scene, _, _ in self._objects:
            local = _apply(T_object_scene, points)
            near = np.flatnonzero(obj.near(local, GAP_RANGE))
            if len(near) == 0:
                continue
            distance = obj.distance(local[near])
            for k in np.unique(surface[near]):
                of_k = surface[near] == k
                gaps[names[k]] = min(gaps[names[k]], float(distance[of_k].min()))
                if distance[of_k].min() <= CONTACT_TOLERANCE:
                    touched[names[k]].append(name)
        return {s: tuple(n) for s, n in touched.items()}, gaps

    @staticmethod
    def _verdict(worst, touched: dict[str, tuple[str, ...]], gaps: dict[str, float]
                 ) -> Judgement:
        depth, obstacle, link, point = worst
        objects = sorted({name for names in touched.values() for name in names})
        grasped = objects[0] if len(objects) == 1 and all(touched.values()) else None
        if depth > PENETRATION_TOLERANCE:
            reason = "table" if obstacle == TABLE else "penetration"
        elif not all(touched.values()):
            reason = "no contact"
        elif grasped is None:
            reason = "two objects"
        else:
            reason = "ok"
        return Judgement(reason == "ok", grasped, depth, obstacle, link, point, touched, gaps,
                         reason)
