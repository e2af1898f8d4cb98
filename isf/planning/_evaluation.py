"""What happens to a sample after its proposal: the fit, the collision check, the repair, the
centring.

:class:`SampleJudge` checks a fitted grasp and, when it collides, repairs it once and checks it
again; a valid grasp is then slid toward the centre of mass (:mod:`isf.planning.centring`);
:class:`SampleWorker` adds the fit. A judge and a worker keep state between calls (the
collision checker's and the fitter's scratch), so a thread must not share one, while everything
they are built from (gripper, object, the memoised collision and repair set-up) is only read.

The loop of :func:`isf.planning.planner.plan` (Algorithm 3) starts samples and takes them back
fitted and checked through one of two evaluators with the same methods (``window``, ``start``,
``finished``, ``fit_time``, ``judges``, used as a context manager):
:class:`LockstepEvaluations` fits the samples in flight together in the calling thread (one
:class:`isf.fitting.engine.LockstepFitter` and one judge) and returns them as they finish;
:class:`ThreadedEvaluations` evaluates each on a pool of threads (one worker each) and returns
them in the order they were started.
"""

from __future__ import annotations

import queue
import time
from collections import deque
from collections.abc import Hashable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from ..collision.checker import CollisionChecker, CollisionReport, HiddenRegion, Plane
from ..config import FitConfig
from ..fitting.engine import LockstepFitter
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..repair.clearance import ClearanceRepair, RepairConfig, repair_penetration
from ..result import FitResult
from ..samplers import Proposal
from .centring import CentringConfig, GraspCentring

__all__ = ["Judged", "LockstepEvaluations", "SampleJudge", "SampleWorker", "ThreadedEvaluations"]


class Judged(NamedTuple):
    """A judged fit: the grasp kept, its collision report, whether it is the repair's, and
    whether it was slid toward the centre of mass (:mod:`isf.planning.centring`)."""

    result: FitResult
    report: CollisionReport
    repaired: bool
    centred: bool = False


class SampleJudge:
    """Collision check of fitted grasps, with one repair of those that collide.

    Args:
        gripper, obj, config: the gripper, the object surface and the fit parameters.
        obstacles: half-spaces the gripper must stay out of, object frame.
        tolerance: penetration depth tolerated, metres.
        hidden: a region the gripper must stay out of (a scene's unseen space), or None; the
            checks and the repair (which pushes links out along its way out) both see it.
        repair: repair colliding grasps (:func:`isf.repair.clearance.repair_penetration`): True with
            the default :class:`isf.RepairConfig`, or the repair parameters to use;
            False for no repair.
        centring: slide valid grasps toward ``center_of_mass``
            (:class:`isf.planning.centring.GraspCentring`) with these parameters; None for no
            centring.
        center_of_mass: the object's centre of mass, object frame, (3,), metres (needed with
            ``centring``).

    Attributes:
        fit_time: seconds spent repairing and centring (fitting work), summed over calls.
        centring_time: the part of ``fit_time`` spent centring, seconds.
        collision_time: seconds spent in collision checks, summed over calls (the centring's
            are in ``centring_time``).
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig, *,
                 obstacles: Sequence[Plane] = (), tolerance: float = 0.002,
                 hidden: HiddenRegion | None = None, repair: bool | RepairConfig = True,
                 centring: CentringConfig | None = None, center_of_mass: np.ndarray | None = None):
        self.gripper, self.obj, self.config = gripper, obj, config
        self.checker = CollisionChecker(gripper, obj, obstacles=obstacles, tolerance=tolerance,
                                        hidden=hidden)
        self.repairer = None if repair is False else ClearanceRepair(
            gripper, obj, repair if isinstance(repair, RepairConfig) else None, obstacles=obstacles,
            hidden=hidden)
        self.centring = None if centring is None else GraspCentring(
            gripper, obj, center_of_mass, self.checker, config, centring)
        self.fit_time = self.collision_time = self.centring_time = 0.0

    def judge(self, result: FitResult) -> Judged:
        """The grasp to keep for a fit and its collision report: the fit itself, or its repair
        when the fit collides and the repaired grasp does not; a valid grasp slid toward the
        centre of mass when the judge centres."""
        judged = self._checked(result)
        if self.centring is None:
            return judged
        t0 = time.perf_counter()
        centred = self.centring.centre(judged.result, judged.report)
        spent = time.perf_counter() - t0
        self.fit_time += spent
        self.centring_time += spent
        if centred.shift == 0.0:
            return judged
        return judged._replace(result=centred.result, report=centred.report, centred=True)

    def _checked(self, result: FitResult) -> Judged:
        """The fit or its repair, with its collision report (see :meth:`judge`)."""
        t0 = time.perf_counter()
        report = self.checker.check(result.T_object_gripper, result.q)
        self.collision_time += time.perf_counter() - t0
        if self.repairer is None or report.collision_free:
            return Judged(result, report, repaired=False)
        t1 = time.perf_counter()
        repaired = repair_penetration(self.gripper, self.obj, result, fit_config=self.config,
                                      repairer=self.repairer)
        t2 = time.perf_counter()
        again = self.checker.check(repaired.T_object_gripper, repaired.q)
        self.collision_time += time.perf_counter() - t2
        self.fit_time += t2 - t1
        if again.collision_free:
            return Judged(repaired, again, repaired=True)
        return Judged(result, report, repaired=False)


class SampleWorker(SampleJudge):
    """A :class:`SampleJudge` that also fits: one sample from its initial state to its verdict.

    Args: as :class:`SampleJudge`.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig, **judge_options):
        super().__init__(gripper, obj, config, **judge_options)
        self.fitter = LockstepFitter(gripper, obj, config)

    def evaluate(self, T_object_gripper: np.ndarray, q: np.ndarray | None) -> Judged:
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


Evaluated = tuple[Hashable, Proposal, FitResult, CollisionReport, bool, bool]
"""A finished sample: its key, its proposal and :class:`Judged`'s four fields."""


class LockstepEvaluations:
    """Samples fitted together in lockstep in the calling thread, each judged as soon as its fit
    ends.

    Args:
        fitter: the fitter the samples run in.
        judge: checks (and repairs) each fitted sample.
        window: samples in flight at most (the batch size).

    Attributes:
        fit_time: seconds spent fitting, summed over calls (the judge counts its repairs).
    """

    def __init__(self, fitter: LockstepFitter, judge: SampleJudge, window: int):
        self.fitter, self.window, self.judges = fitter, window, [judge]
        self._proposals: dict[Hashable, Proposal] = {}
        self.fit_time = 0.0

    def __enter__(self) -> LockstepEvaluations:
        return self

    def __exit__(self, *_) -> None:
        return None

    def start(self, index: Hashable, proposal: Proposal) -> None:
        """Start fitting sample ``index`` from its proposal.

        Raises:
            InvalidInputError: the proposal's pose or joints are invalid.
        """
        self.fitter.add(index, proposal.T_object_gripper, proposal.q)
        self._proposals[index] = proposal

    def finished(self) -> Iterator[Evaluated]:
        """The samples whose fits end next (at least one while any is in flight), in index
        order, each judged as it is taken."""
        t0 = time.perf_counter()
        ended = self.fitter.advance()
        self.fit_time += time.perf_counter() - t0
        for index, result in sorted(ended, key=lambda item: item[0]):
            yield (index, self._proposals.pop(index), *self.judges[0].judge(result))


class ThreadedEvaluations:
    """Samples fitted, checked and repaired on a pool of threads, one worker per thread, and
    taken back in the order they were started (so what the caller sees does not depend on the
    threads' timing).

    Args:
        workers: one :class:`SampleWorker` per thread.
        window: samples in flight at most.

    Attributes:
        fit_time: 0; the workers count their fitting and repairs.
    """

    def __init__(self, workers: list[SampleWorker], window: int):
        self.judges, self.window = workers, window
        self._idle: queue.SimpleQueue[SampleWorker] = queue.SimpleQueue()
        for worker in workers:
            self._idle.put(worker)
        self._pending: deque[tuple[Hashable, Proposal, Future]] = deque()
        self._pool: ThreadPoolExecutor | None = None
        self.fit_time = 0.0

    def __enter__(self) -> ThreadedEvaluations:
        self._pool = ThreadPoolExecutor(len(self.judges), thread_name_prefix="isf-plan")
        return self

    def __exit__(self, *_) -> None:
        for *_, future in self._pending:
            future.cancel()
        self._pool.shutdown(wait=True)

    def _evaluate(self, proposal: Proposal) -> tuple[FitResult, CollisionReport]:
        worker = self._idle.get()  # never waits: no more tasks run than there are workers
        try:
            return worker.evaluate(proposal.T_object_gripper, proposal.q)
        finally:
            self._idle.put(worker)

    def start(self, index: Hashable, proposal: Proposal) -> None:
        """Queue sample ``index`` for the next free thread."""
        self._pending.append((index, proposal, self._pool.submit(self._evaluate, proposal)))

    def finished(self) -> Iterator[Evaluated]:
        """The oldest sample in flight, once its thread is done with it.

        Raises:
            InvalidInputError: the proposal's pose or joints are invalid.
        """
        index, proposal, future = self._pending.popleft()
        yield (index, proposal, *future.result())
