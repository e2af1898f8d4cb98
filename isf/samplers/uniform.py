"""The ``uniform`` sampler: grasp centre on a random surface point, random orientation."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Proposal, Sampler, place_gripper, random_rotation

__all__ = ["UniformSampler"]


@dataclass(eq=False, kw_only=True)
class UniformSampler(Sampler):
    """Grasp centre at an object point drawn uniformly, orientation uniform on SO(3).

    Uniform over surface *samples*, hence over surface area when the object
    points are spread evenly. Takes no parameters and ignores outcomes.
    ``record`` holds ``{"point": index into obj.points}``.
    """

    name = "uniform"
    description = "grasp centre on a uniformly drawn surface point, uniformly random orientation"

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """Propose ``n`` initial grasps (see :meth:`Sampler.propose`)."""
        obj, gripper = self._require_reset()
        index = rng.integers(obj.n_points, size=n)
        T = place_gripper(gripper, obj.points[index], random_rotation(rng, size=n))
        return [Proposal(T[i], record={"point": int(index[i])}) for i in range(n)]
