"""isf sampler plugin ``normal``: approach the object along the inward surface normal.

Registered through the ``isf.samplers`` entry point (see ``pyproject.toml``);
isf never imports this package directly. Use it as
``isf.samplers.get_sampler("normal")``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from isf.exceptions import GripperDescriptionError
from isf.samplers import Proposal, Sampler, place_gripper, random_rotation

if TYPE_CHECKING:
    from isf.gripper import Gripper
    from isf.object_surface import ObjectSurface

__all__ = ["NormalSampler", "__version__"]

__version__ = "0.1.0"


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix of ``v`` (3,), shape (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b``, shape (3, 3)."""
    c = float(a @ b)
    if c < -1.0 + 1e-9:  # opposite: half turn about any axis perpendicular to a
        u = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
        u /= np.linalg.norm(u)
        return 2.0 * np.outer(u, u) - np.eye(3)
    K = _skew(np.cross(a, b))
    return np.eye(3) + K + K @ K / (1.0 + c)


def _spin(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` (radians) about unit ``axis``, shape (3, 3) (Rodrigues)."""
    K = _skew(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


@dataclass(eq=False, kw_only=True)
class NormalSampler(Sampler):
    """Grasp centre on a random surface point, approach axis along its inward normal.

    The gripper's declared approach direction (``gripper.approach``, in the
    ``palm_link`` frame) is turned onto ``-n`` for the surface normal ``n`` at
    a uniformly drawn object point ``p``, with a uniformly random spin about
    that axis, and the grasp centre is placed at ``p``. A gripper without an
    approach direction gets a uniformly random orientation instead.
    ``record`` holds ``{"point": index into obj.points}``. No parameters.

    Attributes:
        approach_gripper: unit approach direction in the gripper frame, shape
            (3,), or None (set by :meth:`reset`).
    """

    name = "normal"
    description = "grasp centre on a random surface point, approaching along its inward normal"

    approach_gripper: np.ndarray | None = field(init=False, repr=False, default=None)

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Resolve the approach axis in the gripper frame (see ``Sampler.reset``).

        Raises:
            GripperDescriptionError: ``gripper.palm_link`` is not a link of the gripper.
        """
        super().reset(obj, gripper, rng)
        self.approach_gripper = None
        if gripper.approach is None:
            return
        approach = np.asarray(gripper.approach, dtype=float)
        if gripper.palm_link is not None:
            poses = gripper.link_poses(gripper.q_initial)
            if gripper.palm_link not in poses:
                raise GripperDescriptionError(
                    gripper.name,
                    [f"palm_link {gripper.palm_link!r} is not a link; use one of {sorted(poses)}"],
                )
            approach = poses[gripper.palm_link][:3, :3] @ approach
        self.approach_gripper = approach / np.linalg.norm(approach)

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """``n`` proposals at uniformly drawn surface points."""
        obj, gripper = self._require_reset()
        index = rng.integers(obj.n_points, size=n)
        if self.approach_gripper is None:
            R = random_rotation(rng, size=n)
        else:
            angles = rng.uniform(0.0, 2.0 * np.pi, size=n)
            R = np.zeros((n, 3, 3))
            for i in range(n):
                inward = -obj.normals[index[i]] / np.linalg.norm(obj.normals[index[i]])
                R[i] = _spin(inward, angles[i]) @ _align(self.approach_gripper, inward)
        T = place_gripper(gripper, obj.points[index], R)
        return [Proposal(T[i], record={"point": int(index[i])}) for i in range(n)]
