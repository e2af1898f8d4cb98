"""Grasp planning by guided sampling (paper Algorithm 3): :func:`plan`.

Each sample takes an initial pose from the sampler, runs ISF (:func:`isf.fit`),
checks the fitted gripper for collisions (:class:`isf.collision.CollisionChecker`)
and reports the outcome back to the sampler, which uses it to guide the next
proposal (the regret bandit does; the uniform sampler ignores it).

Ranking: collision-free grasps first, then grasps whose every contact surface
touches the object, then by mean point-to-plane distance (lower first).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .collision import CollisionChecker, CollisionReport, Plane
from .config import FitConfig
from .fit import fit
from .gripper import Gripper
from .object_surface import ObjectSurface
from .result import FitResult
from .samplers import Outcome, Sampler, get_sampler

__all__ = ["Grasp", "PlanResult", "PlanStats", "plan"]

NO_CONTACT_ERROR = 0.05
"""Error reported to samplers for a fit where some contact surface does not touch the object, metres."""


@dataclass(frozen=True, eq=False)
class Grasp:
    """One evaluated sample.

    Attributes:
        fit: the ISF result (pose ``T_object_gripper``, joints, errors, history).
        collision: the collision report of the fitted gripper.
        sampler_record: what the sampler recorded for this sample (JSON-serialisable).
        sample_index: position of the sample in the planning run, from 0.
    """

    fit: FitResult
    collision: CollisionReport
    sampler_record: dict
    sample_index: int

    @property
    def T_object_gripper(self) -> np.ndarray:
        """Pose of the gripper frame in the object frame, (4, 4)."""
        return self.fit.T_object_gripper

    @property
    def q(self) -> np.ndarray:
        """Joint vector, (n_joints,), metres or radians."""
        return self.fit.q

    @property
    def joints(self) -> dict[str, float]:
        """Joint values by name, metres or radians."""
        return self.fit.joints

    @property
    def collision_free(self) -> bool:
        """True when no link penetrates the object or an obstacle beyond the tolerance."""
        return self.collision.collision_free

    @property
    def valid(self) -> bool:
        """Collision-free and every contact surface touches the object."""
        return self.collision.collision_free and self.fit.all_surfaces_in_contact

    def sort_key(self) -> tuple:
        """Ranking key: collision-free, then all surfaces touching, then mean distance."""
        return (not self.collision_free, not self.fit.all_surfaces_in_contact,
                self.fit.mean_distance, self.sample_index)


@dataclass(frozen=True)
class PlanStats:
    """Figures of one planning run.

    Attributes:
        samples: samples evaluated.
        collision_free: collision-free grasps.
        valid: collision-free grasps whose every contact surface touches the object.
        total_time: wall time of the whole run (set-up included), seconds.
        time_per_collision_free: ``total_time / collision_free`` (inf when none), seconds.
        fit_time: time spent in ISF, seconds.
        collision_time: time spent in collision checks, seconds.
        setup_time: time to prepare the sampler and the collision checker, seconds.
    """

    samples: int
    collision_free: int
    valid: int
    total_time: float
    time_per_collision_free: float
    fit_time: float
    collision_time: float
    setup_time: float


@dataclass(frozen=True, eq=False)
class PlanResult:
    """Every evaluated grasp, ranked best first, with the run's figures.

    Attributes:
        grasps: all evaluated grasps, ranked (see the module docstring).
        stats: timings and counts.
        gripper: the gripper's name.
        object: the object's name.
        sampler: the sampler's name.
        seed: the seed the run used.
        config: the fit parameters.
    """

    grasps: tuple[Grasp, ...]
    stats: PlanStats
    gripper: str
    object: str
    sampler: str
    seed: int | None
    config: FitConfig = field(default_factory=FitConfig)

    @property
    def best(self) -> Grasp | None:
        """The top-ranked grasp, or None if no sample was evaluated."""
        return self.grasps[0] if self.grasps else None

    def collision_free_grasps(self) -> list[Grasp]:
        """The collision-free grasps, ranked."""
        return [g for g in self.grasps if g.collision_free]


def plan(
    gripper: Gripper | str | Path,
    obj: ObjectSurface | str | Path | np.ndarray,
    samples: int = 60,
    sampler: str | Sampler | type[Sampler] = "regret",
    seed: int | None = 0,
    config: FitConfig | None = None,
    *,
    obstacles: Sequence[Plane] = (),
    collision_tolerance: float = 0.002,
    progress: Callable[[int, int, Grasp], None] | None = None,
) -> PlanResult:
    """Plan grasps of an object with a gripper (Algorithm 3).

    Args:
        gripper: a :class:`Gripper`, a bundled gripper name or a URDF path.
        obj: an :class:`ObjectSurface`, a mesh or point-cloud path, or an (N, 3)/(N, 6) array (metres).
        samples: number of samples ``K_s`` to evaluate.
        sampler: a registered sampler name (see :func:`isf.available_samplers`), class or instance.
        seed: seed of the run's random generator; the same seed gives the same result.
        config: ISF parameters; default the paper's.
        obstacles: half-spaces the gripper must not enter (e.g. ``Plane.table(z)``), object frame.
        collision_tolerance: penetration depth tolerated before a grasp counts as colliding, metres.
        progress: called after each sample as ``progress(done, total, grasp)``.

    Returns:
        the ranked :class:`PlanResult`.

    Raises:
        InvalidInputError: ``samples`` is not a positive integer.
        GripperDescriptionError, ObjectLoadError, SamplerNotFound: bad gripper, object or sampler.
    """
    from .exceptions import InvalidInputError
    from .gripper_loading import load_gripper
    from .object_loading import load_object

    started = time.perf_counter()
    if not isinstance(samples, (int, np.integer)) or samples < 1:
        raise InvalidInputError(f"samples must be a positive integer, got {samples!r}")
    config = FitConfig() if config is None else config
    gripper = gripper if isinstance(gripper, Gripper) else load_gripper(gripper)
    obj = obj if isinstance(obj, ObjectSurface) else load_object(obj)
    sampler = get_sampler(sampler)
    rng = np.random.default_rng(seed)
    sampler.reset(obj, gripper, rng)
    checker = CollisionChecker(gripper, obj, obstacles=obstacles, tolerance=collision_tolerance)
    setup_time = time.perf_counter() - started

    grasps: list[Grasp] = []
    fit_time = collision_time = 0.0
    for index in range(samples):
        (proposal,) = sampler.propose(1, rng)
        t0 = time.perf_counter()
        result = fit(gripper, obj, proposal.T_object_gripper, proposal.q, config)
        t1 = time.perf_counter()
        report = checker.check(result.T_object_gripper, result.q)
        t2 = time.perf_counter()
        fit_time += t1 - t0
        collision_time += t2 - t1
        error = result.mean_distance if result.all_surfaces_in_contact else NO_CONTACT_ERROR
        sampler.observe([Outcome(proposal, error=error, collision_free=report.collision_free)])
        grasp = Grasp(result, report, dict(proposal.record), index)
        grasps.append(grasp)
        if progress is not None:
            progress(index + 1, samples, grasp)

    grasps.sort(key=Grasp.sort_key)
    total = time.perf_counter() - started
    n_free = sum(g.collision_free for g in grasps)
    stats = PlanStats(
        samples=samples, collision_free=n_free, valid=sum(g.valid for g in grasps),
        total_time=total, time_per_collision_free=total / n_free if n_free else float("inf"),
        fit_time=fit_time, collision_time=collision_time, setup_time=setup_time,
    )
    return PlanResult(tuple(grasps), stats, gripper.name, obj.name, sampler.name, seed, config)
