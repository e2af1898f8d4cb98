"""Distinct grasps first: a grasp close to a better-ranked one is marked as its duplicate.

Two grasps are **the same grasp** when their tool-centre points (:attr:`isf.Gripper.T_root_tcp`
placed in the object frame, ``T_object_tcp = T_object_gripper @ T_root_tcp``) lie within
``distance`` of each other and their orientations within ``angle``, compared under the
gripper's symmetries: a gripper whose fingers map onto each other when turned by ``2 pi / n``
about the approach axis through the TCP (a parallel jaw: n = 2, a turn of 180 degrees; a
three-finger hand with fingers 120 degrees apart: n = 3) grips the same way in all n turned
poses, so the smallest angle over the n turns counts. Joint values are not compared: the pose
decides where the fingers close.

Defaults (:class:`Diversity`): 1 cm and 30 degrees; the symmetry order is detected from the
contact surfaces (:func:`detect_symmetry`) or declared (``symmetry=n``; 1: none).

The pass (:func:`distinct_first`) is greedy in rank order, as non-maximum suppression: each
grasp is compared with the distinct grasps ranked before it; within reach of one, it is that
grasp's duplicate (``duplicate_of``: the better grasp's rank in the new order), else it is
distinct. Within each tier of the ranking (:func:`isf.plan` passes valid grasps, then the
other collision-free ones, then the colliding ones), the distinct grasps come first, in their
order, then the duplicates, in theirs: a duplicate of a valid grasp still ranks ahead of every
colliding grasp, and a robot taking the first K grasps takes usable ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..exceptions import InvalidInputError
from ..gripper.model import Gripper

__all__ = [
    "DEFAULT_DIVERSITY",
    "MAX_SYMMETRY_ORDER",
    "DistinctOrder",
    "Diversity",
    "detect_symmetry",
    "distinct_first",
    "symmetry_rotations",
]

MAX_SYMMETRY_ORDER = 8
"""Largest rotational symmetry order :func:`detect_symmetry` tries."""


@dataclass(frozen=True)
class Diversity:
    """When two grasps count as one (module docstring).

    Attributes:
        distance: largest distance between two TCP origins of one grasp, metres (default 1 cm).
        angle: largest angle between two TCP orientations of one grasp, radians (default 30
            degrees), after the gripper's symmetric turns.
        symmetry: the order n of the gripper's rotational symmetry about its approach axis
            through the TCP (n turns of ``2 pi / n`` give the same grasp): ``"auto"`` detects it
            (:func:`detect_symmetry`), 1 declares none.
    """

    distance: float = 0.01
    angle: float = math.radians(30.0)
    symmetry: int | str = "auto"

    def __post_init__(self) -> None:
        for name in ("distance", "angle"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0 \
                    or not math.isfinite(value):
                raise InvalidInputError(f"Diversity {name} must be a finite number >= 0, got "
                                        f"{value!r} (metres for distance, radians for angle)")
        s = self.symmetry
        if s != "auto" and (isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1):
            raise InvalidInputError(f"Diversity symmetry must be 'auto' or an integer >= 1 (the "
                                    f"order of the turn about the approach axis), got {s!r}")

    def order(self, gripper: Gripper) -> int:
        """The symmetry order used for ``gripper``: the declared one or the detected one."""
        return detect_symmetry(gripper) if self.symmetry == "auto" else int(self.symmetry)


DEFAULT_DIVERSITY = Diversity()
"""The default of :func:`isf.plan`: 1 cm, 30 degrees, the symmetry detected."""


class DistinctOrder(NamedTuple):
    """The result of :func:`distinct_first` for N ranked grasps.

    Attributes:
        order: indices into the input, distinct grasps first, (N,).
        duplicate_of: per output position, the 1-based output rank of the better grasp it
            duplicates, or 0 for a distinct grasp, (N,).
    """

    order: np.ndarray
    duplicate_of: np.ndarray


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` (radians) about the unit ``axis`` (3,), (3, 3) (Rodrigues)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def symmetry_rotations(gripper: Gripper, order: int) -> np.ndarray:
    """The ``order`` turns of ``2 pi k / order`` about the approach axis, in the TCP frame,
    (order, 3, 3); the first is the identity."""
    axis = gripper.T_root_tcp[:3, :3].T @ gripper.approach_root
    axis = axis / np.linalg.norm(axis)
    return np.array([_rotation(axis, 2.0 * math.pi * k / order) for k in range(order)])


def detect_symmetry(gripper: Gripper, tolerance: float | None = None) -> int:
    """The largest n <= :data:`MAX_SYMMETRY_ORDER` such that turning the contact-surface
    points (at the initial configuration) by ``2 pi / n`` about the approach axis through the
    TCP maps them onto themselves, or 1.

    Args:
        gripper: the gripper.
        tolerance: largest distance of a turned point from the nearest unturned one (and
            back), metres; default 1 mm plus twice the points' largest spacing (the largest
            distance of a point to its nearest neighbour: the samples of two mirrored surfaces
            do not coincide point for point).
    """
    from scipy.spatial import cKDTree

    points, _ = gripper.contact_points(gripper.q_initial)
    T = gripper.T_root_tcp
    centre, axis = T[:3, 3], gripper.approach_root / np.linalg.norm(gripper.approach_root)
    tree = cKDTree(points)
    if tolerance is None:
        spacing = float(tree.query(points, k=2)[0][:, 1].max()) if len(points) > 1 else 0.0
        tolerance = 1e-3 + 2.0 * spacing
    for n in range(MAX_SYMMETRY_ORDER, 1, -1):
        turned = (points - centre) @ _rotation(axis, 2.0 * math.pi / n).T + centre
        if tree.query(turned)[0].max() <= tolerance and \
                cKDTree(turned).query(points)[0].max() <= tolerance:
            return n
    return 1


def distinct_first(T_object_tcp: np.ndarray, rotations: np.ndarray, distance: float,
                   angle: float, tiers: np.ndarray | None = None) -> DistinctOrder:
    """Reorder N ranked grasps so that the distinct ones come first within each tier (module
    docstring).

    Args:
        T_object_tcp: the grasps' TCP poses in the object frame, best first, (N, 4, 4).
        rotations: the gripper's symmetric turns in the TCP frame, (S, 3, 3), the identity
            among them (:func:`symmetry_rotations`).
        distance: largest TCP distance of one grasp, metres.
        angle: largest orientation difference of one grasp, radians.
        tiers: each grasp's tier of the ranking, non-decreasing, (N,) integers; None: one tier.
    """
    T = np.asarray(T_object_tcp, dtype=float).reshape(-1, 4, 4)
    positions, R = T[:, :3, 3], T[:, :3, :3]
    # orientations of every grasp under every turn: (N, S, 3, 3)
    turned = np.einsum("nij,sjk->nsik", R, np.asarray(rotations, dtype=float))
    cos_limit = math.cos(min(angle, math.pi))
    distinct: list[int] = []
    better = np.full(len(T), -1)
    for i in range(len(T)):
        if distinct:
            d = np.asarray(distinct)
            near = np.linalg.norm(positions[d] - positions[i], axis=1) <= distance
            # cos of the angle between R_d and R_i S: (trace(R_d^T R_i S) - 1) / 2
            traces = np.einsum("dji,sji->ds", R[d], turned[i])
            close = near & ((traces.max(axis=1) - 1.0) / 2.0 >= cos_limit - 1e-12)
            if close.any():
                better[i] = d[np.argmax(close)]
                continue
        distinct.append(i)
    tier = np.zeros(len(T), dtype=np.int64) if tiers is None else np.asarray(tiers, np.int64)
    if np.any(np.diff(tier) < 0):
        raise ValueError("distinct_first: tiers must be non-decreasing in rank order")
    order = np.lexsort((np.arange(len(T)), better >= 0, tier)).astype(np.int64)
    rank = np.empty(len(T), dtype=np.int64)
    rank[order] = np.arange(1, len(T) + 1)
    duplicate_of = np.where(better[order] >= 0, rank[np.maximum(better[order], 0)], 0)
    return DistinctOrder(order, duplicate_of.astype(np.int64))
