"""The contact model of a fitted grasp: where the gripper touches the object and how.

:func:`grasp_contacts` turns a grasp (a gripper pose and joints on an object) into
:class:`Contacts`, the input of the metrics of :mod:`isf.quality.wrenches` and
:mod:`isf.quality.gravity`:

1. The first ``surface_points`` contact points of each tagged contact surface (stored farthest
   first, so they cover it evenly) are placed at the grasp and matched to their nearest object
   points; a point *touches* when it lies within
   ``contact_distance`` of the object (the test the fit's ``surface_contact`` uses,
   :attr:`isf.FitResult.surface_contact`) and faces it: its normal within ``max_normal_angle`` of
   the reversed object normal (a pad's rim near an edge of the object does not press on the
   face beyond the edge).
2. The touching points of each contact surface are clustered into *patches*: connected groups
   whose neighbours lie within ``patch_gap`` of each other and whose object normals differ by
   less than ``patch_angle`` (a pad resting on two faces of an edge makes two patches).
3. Each patch becomes point contacts with Coulomb friction, pushing along its mean inward
   object normal: one contact at its centroid when all its points lie within
   ``point_patch_size / 2`` of it (a fingertip), otherwise one at each of up to
   ``patch_corners`` corners of its outline: its points projected onto its mean plane, picked
   farthest first (the farthest from the centroid, then each time the farthest from those
   picked, while that is at least ``point_patch_size / 2`` away). Corner contacts are the
   usual polyhedral model of a flat *soft-finger* or patch contact: together they resist a
   torque about the normal and a tilt of the pad, which a single point contact cannot. A
   contact surface keeps at most ``surface_contacts`` contacts (farthest first again).

Frame: every position and direction is in the object frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface

__all__ = ["ContactModelConfig", "Contacts", "grasp_contacts"]


@dataclass(frozen=True)
class ContactModelConfig:
    """How :func:`grasp_contacts` builds contacts from a grasp (see the module docstring).

    Attributes:
        contact_distance: a contact point within this distance of the object touches it, metres
            (:attr:`isf.FitConfig.contact_distance`).
        surface_points: contact points of each contact surface used, the first (evenly
            spread) ones; ``patch_gap`` should exceed their spacing.
        max_normal_angle: a touching point's normal lies within this of the reversed object
            normal, radians.
        patch_gap: touching points this close or closer belong to one patch, metres.
        patch_angle: object normals of one patch differ by less than this, radians.
        point_patch_size: a patch whose points lie within half this of its centroid is one
            point contact, metres.
        patch_corners: corner contacts of a larger patch, at most.
        surface_contacts: contacts of one contact surface, at most: when its patches make
            more, the farthest first are kept (as corners are picked); this bounds the cost of
            the wrench space (:class:`isf.quality.wrenches.WrenchSpace`).
    """

    contact_distance: float = 0.002
    surface_points: int = 64
    max_normal_angle: float = 0.7854  # 45 degrees
    patch_gap: float = 0.006
    patch_angle: float = 0.5236  # 30 degrees
    point_patch_size: float = 0.004
    patch_corners: int = 3
    surface_contacts: int = 4


@dataclass(frozen=True)
class Contacts:
    """Point contacts of a grasp on an object, object frame.

    Attributes:
        points: contact positions, (C, 3), metres.
        normals: unit inward normals (the direction the gripper pushes), (C, 3).
        surface: the contact surface of each contact, an index into ``surface_names``, (C,).
        patch: the patch of each contact, numbered over the whole grasp from 0, (C,).
        surface_names: the gripper's contact surfaces, in order.
    """

    points: np.ndarray
    normals: np.ndarray
    surface: np.ndarray
    patch: np.ndarray
    surface_names: tuple[str, ...]

    @property
    def count(self) -> int:
        """Number of point contacts."""
        return len(self.points)

    @property
    def patches(self) -> int:
        """Number of patches."""
        return int(self.patch.max()) + 1 if len(self.patch) else 0

    @property
    def touching_surfaces(self) -> int:
        """Number of contact surfaces with at least one contact."""
        return len(np.unique(self.surface))

    @classmethod
    def from_points(cls, points, normals, surface=None) -> Contacts:
        """Point contacts given directly: ``points`` (C, 3) metres, inward ``normals`` (C, 3)
        (normalised here), ``surface`` (C,) the contact surface of each (default one surface
        per contact); each contact is its own patch."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        normals = np.asarray(normals, dtype=float).reshape(-1, 3)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        surface = np.arange(len(points)) if surface is None else np.asarray(surface, dtype=int)
        names = tuple(str(k) for k in range(int(surface.max()) + 1 if len(surface) else 0))
        return cls(points, normals, surface, np.arange(len(points)), names)


def grasp_contacts(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
                   q: np.ndarray, config: ContactModelConfig | None = None) -> Contacts:
    """The contacts of the gripper at pose ``T_object_gripper`` (4, 4) and joints ``q``
    (n_joints,) on ``obj`` (see the module docstring)."""
    config = ContactModelConfig() if config is None else config
    T = np.asarray(T_object_gripper, dtype=float)
    used = gripper.point_rank < config.surface_points
    local, local_normals = gripper.contact_points(np.asarray(q, dtype=float), used)
    placed = local @ T[:3, :3].T + T[:3, 3]
    dist, target = obj.nearest(placed)
    facing = np.einsum("ij,ij->i", local_normals @ T[:3, :3].T, obj.normals[target])
    touching = (dist <= config.contact_distance) & (facing <= -np.cos(config.max_normal_angle))
    point_surface = gripper.point_surface[used]
    points, normals, surfaces, patches = [], [], [], []
    n_patches = 0
    for k in range(len(gripper.surfaces)):
        rows = np.flatnonzero(touching & (point_surface == k))
        if not len(rows):
            continue
        inward = -obj.normals[target[rows]]
        labels, count = _patch_labels(placed[rows], inward, config)
        found = [_patch_contacts(placed[rows][labels == label], inward[labels == label], config)
                 for label in range(count)]
        corners = np.concatenate([c for c, _ in found])
        normal = np.concatenate([np.repeat(n[None], len(c), axis=0) for c, n in found])
        patch = np.concatenate([np.full(len(c), n_patches + j) for j, (c, _) in enumerate(found)])
        keep = _farthest_first(corners - corners.mean(axis=0), config.surface_contacts, 0.0)
        points.append(corners[keep])
        normals.append(normal[keep])
        surfaces.append(np.full(len(keep), k))
        patches.append(patch[keep])
        n_patches += count
    names = tuple(s.name for s in gripper.surfaces)
    if not points:
        return Contacts(np.empty((0, 3)), np.empty((0, 3)), np.empty(0, int), np.empty(0, int),
                        names)
    return Contacts(np.concatenate(points), np.concatenate(normals), np.concatenate(surfaces),
                    np.concatenate(patches), names)


def _patch_labels(points: np.ndarray, normals: np.ndarray,
                  config: ContactModelConfig) -> tuple[np.ndarray, int]:
    """Patch label of each touching point of one surface (M,) and the number of patches: the
    connected components of the graph joining points within ``patch_gap`` whose normals differ
    by less than ``patch_angle`` (labels spread as the smallest index of a component)."""
    gram = points @ points.T
    squared = np.diag(gram)
    near = squared[:, None] + squared[None, :] - 2.0 * gram  # squared distances
    linked = (near <= config.patch_gap ** 2) & (normals @ normals.T >= np.cos(config.patch_angle))
    labels = np.arange(len(points))
    while True:
        spread = np.where(linked, labels[None, :], len(points)).min(axis=1)
        spread = spread[spread]  # pointer jumping: far fewer rounds on long chains
        if np.array_equal(spread, labels):
            break
        labels = spread
    _, labels = np.unique(labels, return_inverse=True)
    return labels, int(labels.max()) + 1


def _patch_contacts(points: np.ndarray, normals: np.ndarray,
                    config: ContactModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """The contact positions of one patch (its centroid, or its corners) (c, 3) and its unit
    inward normal (3,)."""
    normal = normals.mean(axis=0)
    normal /= np.linalg.norm(normal)
    centre = points.mean(axis=0)
    flat = points - centre
    flat -= np.outer(flat @ normal, normal)  # onto the patch's mean plane
    reach = np.einsum("ij,ij->i", flat, flat)
    if len(points) < 3 or 2.0 * np.sqrt(reach.max()) < config.point_patch_size:
        return centre[None], normal
    chosen = _farthest_first(flat, config.patch_corners, 0.5 * config.point_patch_size)
    return centre + flat[chosen], normal


def _farthest_first(offsets: np.ndarray, count: int, min_gap: float) -> list[int]:
    """Up to ``count`` rows of ``offsets`` (M, 3) (from a centre), farthest first: the one
    farthest from the centre, then each time the one farthest from those picked, while that
    is at least ``min_gap`` away (metres)."""
    chosen = [int(np.argmax(np.einsum("ij,ij->i", offsets, offsets)))]
    gaps = np.full(len(offsets), np.inf)
    while len(chosen) < min(count, len(offsets)):
        gaps = np.minimum(gaps, np.linalg.norm(offsets - offsets[chosen[-1]], axis=1))
        if gaps.max() <= min_gap:
            break
        chosen.append(int(np.argmax(gaps)))
    return chosen
