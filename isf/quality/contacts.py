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

:func:`grasps_contacts` builds the contacts of many grasps of one object at once (one
nearest-point query, the patches of all grasps on padded arrays), the same as one at a time.

Frame: every position and direction is in the object frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface

__all__ = ["ContactModelConfig", "Contacts", "grasp_contacts", "grasps_contacts"]


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
    return grasps_contacts(gripper, obj, np.asarray(T_object_gripper, dtype=float)[None],
                           np.asarray(q, dtype=float)[None], config)[0]


def grasps_contacts(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
                    q: np.ndarray, config: ContactModelConfig | None = None) -> list[Contacts]:
    """:func:`grasp_contacts` of many grasps at once: poses ``T_object_gripper`` (G, 4, 4) and
    joints ``q`` (G, n_joints); the same contacts, computed for all grasps, contact surfaces
    and patches together (one nearest-point query, padded arrays instead of a loop per patch)."""
    config = ContactModelConfig() if config is None else config
    poses = np.asarray(T_object_gripper, dtype=float).reshape(-1, 4, 4)
    joints = np.asarray(q, dtype=float).reshape(len(poses), gripper.n_joints)
    names = tuple(s.name for s in gripper.surfaces)
    used = gripper.point_rank < config.surface_points
    point_surface = gripper.point_surface[used]
    placed, normals = [], []
    for T, joint in zip(poses, joints):
        local, local_normals = gripper.contact_points(joint, used)
        placed.append(local @ T[:3, :3].T + T[:3, 3])
        normals.append(local_normals @ T[:3, :3].T)
    if not poses.size or not point_surface.size:
        return [_no_contacts(names) for _ in poses]
    placed, normals = np.concatenate(placed), np.concatenate(normals)
    dist, target = obj.nearest(placed)
    facing = np.einsum("ij,ij->i", normals, obj.normals[target])
    rows = np.flatnonzero((dist <= config.contact_distance)
                          & (facing <= -np.cos(config.max_normal_angle)))
    # groups: the touching points of one contact surface of one grasp, grasp-major
    group = (rows // len(point_surface)) * len(names) + point_surface[rows % len(point_surface)]
    order = np.argsort(group, kind="stable")
    rows, group = rows[order], group[order]
    groups, group_rows = np.unique(group, return_inverse=True)
    points, valid = _padded(placed[rows], group_rows, len(groups))
    inward, _ = _padded(-obj.normals[target[rows]], group_rows, len(groups))
    local_patch, patch_count = _patch_labels(points, inward, valid, config)
    # patches, numbered over all groups in order (within a group by their first point)
    first_patch = np.cumsum(patch_count) - patch_count
    point_patch = (first_patch[:, None] + local_patch)[valid]
    by_patch = np.argsort(point_patch, kind="stable")
    patch_points, patch_valid = _padded(points[valid][by_patch], point_patch[by_patch],
                                        int(patch_count.sum()))
    patch_inward, _ = _padded(inward[valid][by_patch], point_patch[by_patch],
                              int(patch_count.sum()))
    corners, corner_valid, patch_normal = _patch_contacts(patch_points, patch_inward,
                                                          patch_valid, config)
    # each group's contacts: its patches' corners, farthest first
    patch_group = np.repeat(np.arange(len(groups)), patch_count)
    corner_patch = np.repeat(np.arange(len(corners)), corner_valid.sum(axis=1))
    surface_corners, surface_valid = _padded(corners[corner_valid], patch_group[corner_patch],
                                             len(groups))
    corner_patch, _ = _padded(corner_patch[:, None], patch_group[corner_patch], len(groups))
    counts = surface_valid.sum(axis=1)
    centres = surface_corners.sum(axis=1) / counts[:, None]  # as ndarray.mean: in order
    keep = _farthest_first(surface_corners - centres[:, None], surface_valid,
                           config.surface_contacts, 0.0)
    grasp_of_group = groups // len(names)
    per_grasp = [_no_contacts(names) for _ in poses]
    for g in np.unique(grasp_of_group):
        mine = np.flatnonzero(grasp_of_group == g)
        picks = [(m, keep[m][keep[m] >= 0]) for m in mine]
        patch = np.concatenate([corner_patch[m, k, 0].astype(int) for m, k in picks])
        per_grasp[g] = Contacts(np.concatenate([surface_corners[m, k] for m, k in picks]),
                                patch_normal[patch],
                                np.concatenate([np.full(len(k), groups[m] % len(names))
                                                for m, k in picks]),
                                patch - first_patch[mine[0]], names)
    return per_grasp


def _no_contacts(names: tuple[str, ...]) -> Contacts:
    return Contacts(np.empty((0, 3)), np.empty((0, 3)), np.empty(0, int), np.empty(0, int), names)


def _padded(values: np.ndarray, rows: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``values`` (N, k) sorted by their row ``rows`` (N,) laid out as ``count`` rows padded
    with zeros, (count, M, k), and the mask of real entries (count, M), in their order."""
    sizes = np.bincount(rows, minlength=count)
    slot = np.arange(len(rows)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    padded = np.zeros((count, int(sizes.max(initial=1)), values.shape[1]))
    valid = np.zeros(padded.shape[:2], dtype=bool)
    padded[rows, slot] = values
    valid[rows, slot] = True
    return padded, valid


def _patch_labels(points: np.ndarray, normals: np.ndarray, valid: np.ndarray,
                  config: ContactModelConfig) -> tuple[np.ndarray, np.ndarray]:
    """Patch of each touching point of each group (G, M) (padded, mask ``valid``), numbered
    from 0 per group in the order of their first point, and the number of patches per group
    (G,): the connected components of the graph joining points within ``patch_gap`` whose
    normals differ by less than ``patch_angle`` (labels spread as the smallest index of a
    component, by pointer jumping, in the groups whose labels still change)."""
    gram = points @ points.transpose(0, 2, 1)
    squared = np.diagonal(gram, axis1=1, axis2=2)
    near = squared[:, :, None] + squared[:, None, :] - 2.0 * gram  # squared distances
    linked = ((near <= config.patch_gap ** 2)
              & (normals @ normals.transpose(0, 2, 1) >= np.cos(config.patch_angle))
              & valid[:, :, None] & valid[:, None, :])
    size = points.shape[1]
    linked[:, np.arange(size), np.arange(size)] = True  # padding: a component of its own
    labels = np.tile(np.arange(size), (len(valid), 1))
    changing = np.arange(len(valid))
    while changing.size:
        current = labels[changing]
        spread = np.where(linked[changing], current[:, None, :], size).min(axis=2)
        spread = np.take_along_axis(spread, spread, axis=1)  # pointer jumping
        labels[changing] = spread
        changing = changing[(spread != current).any(axis=1)]
    roots = (labels == np.arange(size)) & valid
    number = np.cumsum(roots, axis=1) - 1
    return np.take_along_axis(number, labels, axis=1), roots.sum(axis=1)


def _patch_contacts(points: np.ndarray, normals: np.ndarray, valid: np.ndarray,
                    config: ContactModelConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact positions of each patch (its centroid, or its corners) (P, c, 3) with their
    mask (P, c), and its unit inward normal (P, 3), from its points and object normals
    (P, M, 3), padded (mask ``valid``)."""
    counts = valid.sum(axis=1)
    normal = normals.sum(axis=1) / counts[:, None]  # as ndarray.mean: summed in order
    centre = points.sum(axis=1) / counts[:, None]
    flat = points - centre[:, None]
    for k, m in enumerate(counts):  # the BLAS products per patch, as on one patch
        normal[k] /= np.linalg.norm(normal[k])
        flat[k, :m] -= np.outer(flat[k, :m] @ normal[k], normal[k])  # onto its mean plane
    reach = np.where(valid, np.einsum("pij,pij->pi", flat, flat), -np.inf)
    spread = (counts >= 3) & (2.0 * np.sqrt(reach.max(axis=1)) >= config.point_patch_size)
    chosen = _farthest_first(flat, valid, config.patch_corners, 0.5 * config.point_patch_size)
    chosen[~spread, 1:] = -1
    corners = centre[:, None] + np.take_along_axis(flat, np.maximum(chosen, 0)[:, :, None], axis=1)
    corners[~spread, 0] = centre[~spread]
    return corners, chosen >= 0, normal


def _farthest_first(offsets: np.ndarray, valid: np.ndarray, count: int,
                    min_gap: float) -> np.ndarray:
    """Up to ``count`` entries of each row of ``offsets`` (R, M, 3) (from a centre; padded, mask
    ``valid``), farthest first: the one farthest from the centre, then each time the one
    farthest from those picked, while that is at least ``min_gap`` away (metres); (R, count)
    indices, -1 past the last."""
    rows = np.arange(len(offsets))
    squared = np.where(valid, np.einsum("pij,pij->pi", offsets, offsets), -np.inf)
    chosen = np.full((len(offsets), count), -1)
    chosen[:, 0] = np.argmax(squared, axis=1)
    gaps = np.where(valid, np.inf, -np.inf)
    going = valid.any(axis=1)
    for pick in range(1, min(count, offsets.shape[1])):
        going &= valid.sum(axis=1) > pick
        if not going.any():
            break
        step = offsets - offsets[rows, chosen[:, pick - 1]][:, None]
        gaps = np.minimum(gaps, np.sqrt(np.add.reduce(step * step, axis=2)))  # as linalg.norm
        going &= gaps.max(axis=1) > min_gap
        chosen[going, pick] = np.argmax(gaps[going], axis=1)
    return chosen
