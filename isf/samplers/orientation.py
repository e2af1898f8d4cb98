"""Initial orientations: uniformly random (the paper), or the hand's approach axis facing the object.

A gripper may declare an approach direction (``<isf:gripper palm_link approach>``): the
direction, in its palm link frame, along which the hand moves towards the object. Facing
orientations turn that axis onto an inward object direction (minus the surface normal at
the grasp centre) and spin the hand about it uniformly at random.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ConfigError, GripperDescriptionError
from ..se3 import exp_so3, skew
from .base import random_rotation

if TYPE_CHECKING:
    from ..gripper.model import Gripper

__all__ = [
    "ORIENTATIONS",
    "approach_direction",
    "check_orientation",
    "facing_rotations",
    "initial_rotations",
    "resolve_approach",
]

ORIENTATIONS = ("auto", "approach", "random")
"""``auto``: facing when the gripper declares an approach, else random; ``approach``: always
facing (an error for a gripper without one); ``random``: uniform on SO(3), as in the paper."""


def approach_direction(gripper: Gripper) -> np.ndarray | None:
    """The declared approach direction in the gripper frame, unit (3,), or None.

    Raises:
        GripperDescriptionError: ``gripper.palm_link`` is not a link of the gripper.
    """
    if gripper.approach is None:
        return None
    approach = np.asarray(gripper.approach, dtype=float)
    if gripper.palm_link is not None:
        poses = gripper.link_poses(gripper.q_initial)
        if gripper.palm_link not in poses:
            raise GripperDescriptionError(
                gripper.name, [f"palm_link {gripper.palm_link!r} is not a link; use one of {sorted(poses)}"]
            )
        approach = poses[gripper.palm_link][:3, :3] @ approach
    return approach / np.linalg.norm(approach)


def check_orientation(orientation: str, sampler: str) -> None:
    """Raise ConfigError unless ``orientation`` is one of :data:`ORIENTATIONS`."""
    if orientation not in ORIENTATIONS:
        raise ConfigError(f"{sampler}: orientation must be one of {ORIENTATIONS}, got {orientation!r}")


def resolve_approach(orientation: str, gripper: Gripper, sampler: str) -> np.ndarray | None:
    """The approach axis a sampler with ``orientation`` should use for ``gripper``, or None for random.

    Raises:
        ConfigError: ``orientation`` is unknown, or ``approach`` for a gripper without one.
    """
    check_orientation(orientation, sampler)
    if orientation == "random":
        return None
    approach = approach_direction(gripper)
    if approach is None and orientation == "approach":
        raise ConfigError(
            f"{sampler}: orientation='approach' needs a gripper that declares one; add "
            f"<isf:gripper approach=\"x y z\"/> to {gripper.name} or use orientation='random'"
        )
    return approach


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b``, (3, 3)."""
    c = float(a @ b)
    if c < -1.0 + 1e-9:  # opposite: half turn about any axis perpendicular to a
        u = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
        u /= np.linalg.norm(u)
        return 2.0 * np.outer(u, u) - np.eye(3)
    K = skew(np.cross(a, b))
    return np.eye(3) + K + K @ K / (1.0 + c)


def facing_rotations(approach: np.ndarray, inward: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Rotations ``R_object_gripper`` turning ``approach`` onto each inward direction.

    Args:
        approach: unit approach direction in the gripper frame, (3,).
        inward: directions in the object frame (need not be unit), (n, 3).
        rng: random generator (for the spin about each direction).

    Returns:
        proper rotations, (n, 3, 3), each with a uniformly random spin about its direction.
    """
    inward = inward / np.linalg.norm(inward, axis=1, keepdims=True)
    angles = rng.uniform(0.0, 2.0 * np.pi, size=len(inward))
    return np.stack([exp_so3(angle * d) @ _align(approach, d) for angle, d in zip(angles, inward)])


def initial_rotations(approach: np.ndarray | None, inward: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Facing rotations when ``approach`` is given, else uniformly random ones, (n, 3, 3)."""
    if approach is None:
        return random_rotation(rng, size=len(inward))
    return facing_rotations(approach, inward, rng)
