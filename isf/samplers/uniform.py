"""The ``uniform`` sampler: grasp centre on a uniformly drawn surface point."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .base import Proposal, Sampler, place_gripper
from .orientation import check_orientation, initial_rotations, resolve_approach

if TYPE_CHECKING:
    from ..gripper.model import Gripper
    from ..object.surface import ObjectSurface

__all__ = ["UniformSampler"]


@dataclass(eq=False, kw_only=True)
class UniformSampler(Sampler):
    """Grasp centre at an object point drawn uniformly; ignores outcomes.

    Uniform over surface *samples*, hence over surface area when the object
    points are spread evenly. ``record`` holds ``{"point": index into obj.points}``.

    Args:
        orientation: ``auto`` (default: the gripper's approach axis along the inward
            normal at the point when it declares one, else random), ``approach`` or
            ``random`` (uniform on SO(3), the paper's); see :mod:`isf.samplers.orientation`.
    """

    name = "uniform"
    description = "grasp centre on a uniformly drawn surface point, facing it (or random orientation)"

    orientation: str = "auto"
    _approach: np.ndarray | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        check_orientation(self.orientation, self.name)

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Resolve the approach axis (see :meth:`Sampler.reset`).

        Raises:
            ConfigError: an unknown ``orientation``, or ``approach`` for a gripper without one.
        """
        super().reset(obj, gripper, rng)
        self._approach = resolve_approach(self.orientation, gripper, self.name)

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """Propose ``n`` initial grasps (see :meth:`Sampler.propose`)."""
        obj, gripper = self._require_reset()
        index = rng.integers(obj.n_points, size=n)
        R = initial_rotations(self._approach, -obj.normals[index], rng)
        T = place_gripper(gripper, obj.points[index], R)
        return [Proposal(T[i], record={"point": int(index[i])}) for i in range(n)]
