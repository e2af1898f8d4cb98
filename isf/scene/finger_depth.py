"""How deep a grasp's fingers may sit in the true surface, judged from the observed one point by
point: each finger point's depth into the observed surface plus the local scatter there.

Settling (:mod:`isf.scene.settle`) takes a grasp out of the observed surface by the scene's
noise, one width for the whole surface. Where the surface is not one smooth face the observation
is worse than that: at an object's edge or rim the depth camera loses pixels, mixes foreground
and background, and the smoothing onto local planes rounds the edge off, so the observed points
there lie up to 1-2 mm inside the true surface, and a finger laid along a face that reaches over
the edge presses into the true corner (on simulated scenes, most settled grasps that entered
a ground-truth object 2-5 mm deep did so at an edge, where the true surface normals turn by
45-170 degrees within 4 mm).

The local scatter of a surface point (``Scene.scatter``: the RMS distance of its 16 nearest
neighbours, ``isf.scene.NORMAL_NEIGHBOURS``, from their local plane, before the smoothing)
measures that uncertainty: the sensor noise on a flat face, more where the neighbourhood bends
over an edge. :class:`FingerDepth` bounds how deep each finger (a link carrying a contact
surface) may be in the true surface:

    bound = max over the finger's surface samples p near the observed surface of
            depth(p) + NOISE_MARGIN x scatter(p),

where ``depth(p)`` is the collision check's depth estimate (the smallest of
``(o_k - p) . n_k`` over the :data:`NEIGHBOURS` nearest observed points ``o_k`` with normals
``n_k``: > 0 inside, when ``p`` lies below every nearby tangent plane) and ``scatter(p)`` the
largest local scatter among those points. Only samples within :data:`NEAR` of an observed point
count (farther ones are judged by the unseen space and the collision check). Settling
(:class:`isf.scene.settle.Settler`) moves a settled grasp whose bound exceeds the collision
tolerance until it is within it, and the planner ranks the settled grasps it could not bring
within it after those within it.

Frames: poses are ``T_scene_gripper``; points in the scene frame, metres.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..gripper.model import Gripper

__all__ = ["FINGER_SPACING", "NEAR", "NEIGHBOURS", "FingerDepth"]

FINGER_SPACING = 0.0015
"""Spacing of the surface samples of each finger, metres (about; area / spacing^2 samples)."""

NEAR = 0.004
"""A finger sample counts when an observed point lies within this distance, metres."""

NEIGHBOURS = 6
"""Observed points whose tangent planes give a finger sample's depth (as the collision check)."""

_MAX_SAMPLES = 4000  # per finger geometry


class FingerDepth:
    """The local depth bound of a gripper's fingers on one observed surface (module docstring).

    Args:
        gripper: the gripper; its contact links' collision geometries are sampled.
        points: (N, 3) observed surface points, scene frame, metres.
        normals: (N, 3) their outward unit normals.
        scatter: (N,) their local scatter, metres.
        margin: how many local scatter widths the bound adds to the depth.
    """

    def __init__(self, gripper: Gripper, points: np.ndarray, normals: np.ndarray,
                 scatter: np.ndarray, margin: float):
        self.gripper = gripper
        self.points = np.asarray(points, dtype=float)
        self.normals = np.asarray(normals, dtype=float)
        self.scatter = np.asarray(scatter, dtype=float)
        self.margin = float(margin)
        self._tree = cKDTree(self.points)
        fingers = set(gripper.contact_links)
        self._samples = {}
        for geometry in gripper.geometries:
            if geometry.link in fingers:
                samples = _surface_samples(geometry.vertices, geometry.faces)
                previous = self._samples.get(geometry.link)
                self._samples[geometry.link] = samples if previous is None else \
                    np.concatenate([previous, samples])

    def bound(self, T_scene_gripper: np.ndarray, q: np.ndarray) -> float:
        """The fingers' local depth bound at pose ``T_scene_gripper`` (4, 4) and joints ``q``,
        metres (-inf when no finger sample is near the observed surface)."""
        return max(self.by_finger(T_scene_gripper, q).values(), default=-np.inf)

    def by_finger(self, T_scene_gripper: np.ndarray, q: np.ndarray) -> dict[str, float]:
        """Each finger's local depth bound (link name -> metres; -inf for a finger with no
        sample near the observed surface) at pose ``T_scene_gripper`` (4, 4), joints ``q``."""
        poses = self.gripper.link_poses(np.asarray(q, dtype=float))
        T = np.asarray(T_scene_gripper, dtype=float)
        out = {}
        for link, samples in self._samples.items():
            T_scene_link = T @ poses[link]
            posed = samples @ T_scene_link[:3, :3].T + T_scene_link[:3, 3]
            out[link] = float(self.bounds(posed).max(initial=-np.inf))
        return out

    def bounds(self, samples: np.ndarray) -> np.ndarray:
        """``depth + margin x scatter`` of each of ``samples`` (M, 3) (scene frame) that lies
        within :data:`NEAR` of an observed point, metres (the others are left out)."""
        distance, _ = self._tree.query(samples, distance_upper_bound=NEAR, workers=1)
        samples = samples[distance < NEAR]
        k = min(NEIGHBOURS, len(self.points))
        _, nearest = self._tree.query(samples, k=k, workers=1)
        nearest = nearest.reshape(len(samples), k)
        offsets = np.einsum("ikj,ikj->ik", self.points[nearest] - samples[:, None, :],
                            self.normals[nearest])
        depth = offsets.min(axis=1)  # inside only when below every nearby tangent plane
        return depth + self.margin * self.scatter[nearest].max(axis=1)


def _surface_samples(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """A mesh's vertices and about area / FINGER_SPACING^2 points on its faces (fixed seed),
    (S, 3) in the mesh's frame."""
    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces), process=False)
    count = int(min(_MAX_SAMPLES, max(16, np.ceil(mesh.area / FINGER_SPACING ** 2))))
    sampled, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
    return np.concatenate([np.asarray(vertices, dtype=float), sampled])
