"""What happens to a sample after its proposal: the fit, the collision check, the repair.

:class:`SampleJudge` checks a fitted grasp and, when it collides, repairs it once and checks it
again; :class:`SampleWorker` adds the fit. :func:`isf.plan` keeps one judge for its sequential
loop, or one worker per thread: a judge and a worker keep state between calls (the collision
checker's and the fitter's scratch), so a thread must not share one, while everything they are
built from (gripper, object, the memoised collision and repair set-up) is only read.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from ..repair.clearance import ClearanceRepair, RepairConfig, repair_penetration
from ..collision.checker import CollisionChecker, CollisionReport, Plane
from ..config import FitConfig
from ..gripper.model import Gripper
from ..fitting.engine import LockstepFitter
from ..object.surface import ObjectSurface
from ..result import FitResult

__all__ = ["SampleJudge", "SampleWorker"]


class SampleJudge:
    """Collision check of fitted grasps, with one repair of those that collide.

    Args:
        gripper, obj, config: the gripper, the object surface and the fit parameters.
        obstacles: half-spaces the gripper must stay out of, object frame.
        tolerance: penetration depth tolerated, metres.
        repair: repair colliding grasps (:func:`isf.repair.clearance.repair_penetration`): True with
            the default :class:`isf.RepairConfig`, or the repair parameters to use;
            False for no repair.

    Attributes:
        fit_time: seconds spent repairing (the repair is fitting work), summed over calls.
        collision_time: seconds spent in collision checks, summed over calls.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig, *,
                 obstacles: Sequence[Plane] = (), tolerance: float = 0.002,
                 repair: bool | RepairConfig = True):
        self.gripper, self.obj, self.config = gripper, obj, config
        self.checker = CollisionChecker(gripper, obj, obstacles=obstacles, tolerance=tolerance)
        self.repairer = None if repair is False else ClearanceRepair(
            gripper, obj, repair if isinstance(repair, RepairConfig) else None, obstacles=obstacles)
        self.fit_time = self.collision_time = 0.0

    def judge(self, result: FitResult) -> tuple[FitResult, CollisionReport]:
        """The grasp to keep for a fit and its collision report: the fit itself, or its repair
        when the fit collides and the repaired grasp does not."""
        t0 = time.perf_counter()
        report = self.checker.check(result.T_object_gripper, result.q)
        self.collision_time += time.perf_counter() - t0
        if self.repairer is None or report.collision_free:
            return result, report
        t1 = time.perf_counter()
        repaired = repair_penetration(self.gripper, self.obj, result, fit_config=self.config,
                                      repairer=self.repairer)
        t2 = time.perf_counter()
        again = self.checker.check(repaired.T_object_gripper, repaired.q)
        self.collision_time += time.perf_counter() - t2
        self.fit_time += t2 - t1
        return (repaired, again) if again.collision_free else (result, report)


class SampleWorker(SampleJudge):
    """A :class:`SampleJudge` that also fits: one sample from its initial state to its verdict.

    Args: as :class:`SampleJudge`.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig, **judge_options):
        super().__init__(gripper, obj, config, **judge_options)
        self.fitter = LockstepFitter(gripper, obj, config)

    def evaluate(self, T_object_gripper: np.ndarray,
                 q: np.ndarray | None) -> tuple[FitResult, CollisionReport]:
        """Fit from palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,; None:
        the gripper's initial joints), then :meth:`judge` the fit.

        Raises:
            InvalidInputError: the pose is not a rigid transform or ``q`` is invalid.
        """
        t0 = time.perf_counter()
        self.fitter.add(0, T_object_gripper, q)
        finished = []
        while not finished:
            finished = self.fitter.advance()
        self.fit_time += time.perf_counter() - t0
        return self.judge(finished[0][1])
