"""isf sampler plugin ``normal``: approach the object along the inward surface normal.

Registered through the ``isf.samplers`` entry point (see ``pyproject.toml``);
isf never imports this package directly. Use it as
``isf.samplers.get_sampler("normal")``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from isf.samplers import Proposal, Sampler, place_gripper
from isf.samplers.orientation import approach_direction, initial_rotations

if TYPE_CHECKING:
    from isf.gripper.model import Gripper
    from isf.object.surface import ObjectSurface

__all__ = ["NormalSampler", "__version__"]

__version__ = "0.1.0"


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
        self.approach_gripper = approach_direction(gripper)

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """``n`` proposals at uniformly drawn surface points."""
        obj, gripper = self._require_reset()
        index = rng.integers(obj.n_points, size=n)
        R = initial_rotations(self.approach_gripper, -obj.normals[index], rng)
        T = place_gripper(gripper, obj.points[index], R)
        return [Proposal(T[i], record={"point": int(index[i])}) for i in range(n)]
