"""Grasp planning by guided sampling (paper Algorithm 3): :func:`plan`.

:func:`plan` is the paper's loop: the sampler proposes an initial state (guided sampling, line 4),
ISF fits the gripper from it and the fitted gripper is checked for collisions
(:class:`isf.collision.checker.CollisionChecker`) (line 5), and the outcome goes back to the
sampler (line 6), which uses it to guide the next proposal (the regret bandit does; the uniform
sampler ignores it). ISF is Algorithm 2: :func:`isf.fit`, the compiled engine
(:class:`isf.fitting.engine.LockstepFitter`), checked against the plain-Python reference
:func:`isf.fitting.reference.fit`, whose IPFO is Algorithm 1 (:func:`isf.fitting.reference.ipfo`).

The loop keeps up to a window of samples in flight (proposed, not yet observed); by default the
window is one sample, which is the paper's loop: propose, fit, check, observe. Two evaluators run
the samples in flight (:mod:`isf.planning._evaluation`); the loop is the same for both:

* ``batch_size = B > 1``: up to B samples are fitted at once in lockstep in the calling thread
  (:class:`isf.fitting.engine.LockstepFitter`): each keeps its own ISF state and stop rule, and a
  finished sample is checked, reported to the sampler and replaced by a new proposal straight
  away, so the sampler learns from every outcome with a delay of at most ``B - 1`` samples. The
  ISF rounds are compiled (:mod:`isf.fitting.engine_kernel`), so a batch does not save time; it
  is there for samplers that propose in batches.
* ``workers = W > 1``: the samples run on W threads (the compiled fitting, checking and repair
  release Python's GIL, so the threads share the cores), each thread fitting, checking and
  repairing one sample at a time (:class:`isf.planning._evaluation.SampleWorker`). The window
  is ``SAMPLES_PER_WORKER * W`` (``2W``) and outcomes are reported in the order the samples
  were proposed, so sample ``i + 2W`` is proposed once sample ``i`` is observed: the plan
  depends on W and the seed but not on the threads' timing. The window is twice the threads so
  that a thread whose sample ended early takes the next one instead of waiting for a slower
  sample ahead of it to be observed.

A sampler may hold fewer in flight (:meth:`isf.Sampler.in_flight_limit`; the regret sampler
does while it explores). Each fit is the fit it would be alone.

A fitted grasp that collides is repaired once (``repair_collisions``, on by default;
:mod:`isf.repair.clearance`): the links that penetrate are pushed out while the contact surfaces
are pulled back onto the object, and the repaired grasp replaces the fit when the re-check
finds it collision-free. Multi-fingered hands need this: ISF fits only the tagged fingertip
surfaces, and the links behind them can end inside the object.

A valid grasp (collision-free, every contact surface touching) is then slid toward the object's
centre of mass along the directions its fit leaves free (``centring``, on by default;
:mod:`isf.planning.centring`): a flat pad fits a flat face equally well anywhere on it, and a
grip near the centre of mass resists the object's weight best. Scenes are not centred.

Ranking: collision-free grasps first, then grasps whose every contact surface
touches the object, then (on a scene) grasps that rest on one piece of the scene's surface
rather than on several (:mod:`isf.scene.segments`), then (on a scene) the grasps settled within
the scene's contact allowance (:mod:`isf.scene.settle`), then (on a scene) the settled grasps
whose fingers keep within their local depth bound (:mod:`isf.scene.finger_depth`), then by mean
point-to-plane distance
(lower first): the paper's ranking, ``rank="fit"``. By default (``rank="quality"``) the valid
grasps are ranked by what their contacts resist instead (:mod:`isf.quality`:
:func:`isf.quality.grasp_quality.quality_rank_key`: a closing that meets the object with the
contact surfaces first (:mod:`isf.quality.closing`), then a balanced squeeze, then holding
their weight in every gravity direction, then contacts nearest the centre of mass, then the
Ferrari-Canny epsilon, then the fitting error),
ahead of the others in the order above. Their quality is computed once the loop ends, or as
each valid grasp arrives for a sampler that hears it (:meth:`isf.Sampler.hears_quality`:
:attr:`isf.samplers.Outcome.holds` tells it whether the ranking expects the grasp to hold).
After the ranking, distinct grasps come first: a grasp within 1 cm and 30 degrees
(about the TCP, under the gripper's symmetry) of a better one is marked ``duplicate_of`` and
ranked after the distinct ones of its tier (valid and settled within the bound, valid and
settled beyond it, valid but unsettled, other collision-free, colliding;
:mod:`isf.planning.diversity`).

Scenes: :func:`plan` takes an :class:`isf.scene.Scene` (what depth cameras saw) wherever it
takes an object. ISF fits the scene's observed surface, unsegmented; the collision checks add
the scene's table to the obstacles and its unseen space (:mod:`isf.scene.unseen`) as a region
no link may enter; each collision-free grasp is then settled out of the observed surface by what
its noise could hide (:mod:`isf.scene.settle`); the object frame of the results is the scene frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..collision.checker import CollisionReport, Plane
from ..config import FitConfig
from ..fitting.engine import LockstepFitter
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..quality.closing import closing_obstructions
from ..quality.grasp_quality import (
    GraspQuality,
    ObjectProperties,
    QualityConfig,
    expected_to_hold,
    grasps_quality,
    object_properties,
    quality_rank_key,
)
from ..repair.clearance import RepairConfig
from ..result import FitResult, FitStatus
from ..samplers import NO_CONTACT_ERROR, Outcome, Proposal, Sampler, get_sampler
from ..scene.loading import Scene
from ..scene.settle import Settler
from ._evaluation import LockstepEvaluations, SampleJudge, SampleWorker, ThreadedEvaluations
from ._working_surface import resolve_spacing, working_surface
from .centring import CentringConfig
from .diversity import DEFAULT_DIVERSITY, Diversity, distinct_first, symmetry_rotations
from .span import warn_if_outside_span

__all__ = ["Grasp", "PlanResult", "PlanStats", "plan"]

BATCH_SIZE = 1
"""Default number of samples fitted at once by :func:`plan`: one, the paper's sequential loop
(see the module docstring)."""

SAMPLES_PER_WORKER = 2
"""Samples :func:`plan` keeps in flight per worker thread when ``workers > 1`` (see the module
docstring)."""


@dataclass(frozen=True, eq=False)
class Grasp:
    """One evaluated sample.

    Attributes:
        fit: the ISF result (pose ``T_object_gripper``, joints, errors, history).
        collision: the collision report of the fitted gripper.
        sampler_record: what the sampler recorded for this sample (JSON-serialisable).
        sample_index: position of the sample in the planning run, from 0.
        pieces: on a scene, how many of its surface pieces the contact surfaces rest on
            (:meth:`isf.scene.SceneSegments.touched`; more than 1 is likely two objects);
            None when planning on an object.
        repaired: True when the fit collided and this is its collision repair
            (:func:`isf.repair.clearance.repair_penetration`): then ``fit`` is the repaired
            grasp, whose ``history`` is the ISF fit's and ends before the repair moved it (the
            last record's joints are not the grasp's).
        settled: on a scene, True when the grasp was settled within the scene's contact
            allowance (:mod:`isf.scene.settle`: then ``fit`` and ``collision`` are the settled
            state's), False when a collision-free grasp could not be (it keeps its planned
            state and ranks after the settled ones); None on an object or for a grasp that
            collides.
        within_bound: on a scene, for a settled grasp, True when its fingers' local depth
            bound (:mod:`isf.scene.finger_depth`: depth into the observed surface plus the
            local scatter margin) is within the collision tolerance, False when it is not (it
            ranks after the settled grasps within it, before the unsettled ones); None
            otherwise.
        centred: True when the grasp was slid toward the centre of mass after its fit (and
            repair) (:mod:`isf.planning.centring`): then ``fit`` is the slid grasp (its joints
            re-closed onto the object when the slide needed it), whose ``history`` ends before
            the slide.
        duplicate_of: the rank (from 1) of the better grasp this one repeats (within the
            run's :class:`isf.planning.diversity.Diversity`), or None for a distinct grasp.
        quality: what its contacts resist (:func:`isf.quality.grasp_quality.grasp_quality`), computed for
            the valid grasps of a plan ranked by quality; None otherwise.
        closing_obstructed_by: the links that would take the grip from the contact surfaces as
            the fingers close (:func:`isf.quality.closing.closing_obstructions`: no contact
            surface, deeper in the object than a contact surface whose every closing joint
            moves them too); empty when none, computed with :attr:`quality`; None otherwise.
    """

    fit: FitResult
    collision: CollisionReport
    sampler_record: dict
    sample_index: int
    pieces: int | None = None
    repaired: bool = False
    settled: bool | None = None
    duplicate_of: int | None = None
    quality: GraspQuality | None = None
    closing_obstructed_by: tuple[str, ...] | None = None
    within_bound: bool | None = None
    centred: bool = False

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
    def one_piece(self) -> bool:
        """False when the contact surfaces rest on more than one piece of a scene's surface."""
        return self.pieces is None or self.pieces <= 1

    @property
    def in_contact(self) -> bool:
        """Every contact surface touches the object at the end of a fit that kept its contacts
        (a fit that lost them, :attr:`FitStatus.LOST_CONTACT`, has no fitting error and is no
        grasp, whatever its last pose grazes)."""
        return self.fit.status is not FitStatus.LOST_CONTACT and self.fit.all_surfaces_in_contact

    @property
    def valid(self) -> bool:
        """Collision-free, :attr:`in_contact`, and (on a scene) resting on one piece of its
        surface."""
        return self.collision.collision_free and self.in_contact and self.one_piece

    def sort_key(self) -> tuple:
        """Ranking key: collision-free, then :attr:`in_contact`, then one piece, then settled
        (on a scene), then :attr:`within_bound`, then mean distance; for a grasp with a
        :attr:`quality` record (a plan ranked by quality),
        :func:`isf.quality.grasp_quality.quality_rank_key` (quality, then mean distance) instead of the mean
        distance."""
        if self.quality is None:
            return (not self.collision_free, not self.in_contact, not self.one_piece,
                    self.settled is False, self.within_bound is False, self.fit.mean_distance,
                    self.sample_index)
        return (not self.collision_free, not self.in_contact, not self.one_piece,
                self.settled is False, self.within_bound is False,
                *quality_rank_key(self.quality, self.fit.mean_distance,
                                  closing_obstructed=bool(self.closing_obstructed_by)),
                self.sample_index)


@dataclass(frozen=True)
class PlanStats:
    """Figures of one planning run.

    Attributes:
        samples: samples evaluated.
        collision_free: collision-free grasps.
        valid: collision-free grasps whose every contact surface touches the object (on a
            scene: one piece of it; see :attr:`Grasp.valid`).
        total_time: wall time of the whole run (set-up included), seconds.
        time_per_collision_free: ``total_time / collision_free`` (inf when none), seconds.
        fit_time: time spent in ISF and in repairs, seconds (summed over the worker threads,
            so with ``workers > 1`` it may exceed ``total_time``).
        collision_time: time spent in collision checks, seconds (summed likewise).
        setup_time: time to prepare the sampler and the collision checker, seconds.
        batch_size: samples fitted at once (see :func:`plan`).
        surface_points: object points the run matched against (see ``working_spacing`` of
            :func:`plan`); 0 when not recorded.
        workers: threads that evaluated samples (see :func:`plan`).
        quality_time: time spent computing the valid grasps' quality and sorting by it, seconds
            (part of ``total_time``; 0 with ``rank="fit"``).
        centring_time: time spent sliding valid grasps toward the centre of mass, seconds
            (part of ``fit_time``; 0 without centring).
    """

    samples: int
    collision_free: int
    valid: int
    total_time: float
    time_per_collision_free: float
    fit_time: float
    collision_time: float
    setup_time: float
    batch_size: int = 1
    surface_points: int = 0
    workers: int = 1
    quality_time: float = 0.0
    centring_time: float = 0.0


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
        repair: the collision repair's parameters; None when the run did not repair.
        scene: the :class:`isf.scene.Scene` planned on (its frame is the object frame of the
            grasps), or None for an object.
        diversity: how duplicates were told apart, its ``symmetry`` the order used (detected
            or declared); None when the run kept the plain ranking.
        gripper_model: the :class:`Gripper` planned with (its TCP, joints, URDF file).
        rank: how the grasps were ranked: ``"quality"`` or ``"fit"`` (see :func:`plan`).
        quality: the :class:`isf.quality.grasp_quality.QualityConfig` of the quality ranking; None with
            ``rank="fit"``.
        centring: the centring's parameters (:mod:`isf.planning.centring`); None when the run
            did not centre its grasps.
    """

    grasps: tuple[Grasp, ...]
    stats: PlanStats
    gripper: str
    object: str
    sampler: str
    seed: int | None
    config: FitConfig = field(default_factory=FitConfig)
    repair: RepairConfig | None = None
    scene: Scene | None = None
    diversity: Diversity | None = None
    gripper_model: Gripper | None = None
    rank: str = "fit"
    quality: QualityConfig | None = None
    centring: CentringConfig | None = None

    @property
    def best(self) -> Grasp | None:
        """The top-ranked grasp, or None if no sample was evaluated."""
        return self.grasps[0] if self.grasps else None

    def collision_free_grasps(self) -> list[Grasp]:
        """The collision-free grasps, ranked."""
        return [g for g in self.grasps if g.collision_free]


def _distinct_first(grasps: list[Grasp], gripper: Gripper, diversity: Diversity) -> list[Grasp]:
    """The ranked ``grasps`` with the distinct ones first and the others marked
    ``duplicate_of`` (:func:`isf.planning.diversity.distinct_first`)."""
    if not grasps:
        return grasps
    T_object_tcp = np.array([g.T_object_gripper for g in grasps]) @ gripper.T_root_tcp
    tiers = np.array([(2 if g.settled is False else 1 if g.within_bound is False else 0)
                      if g.valid else 3 if g.collision_free else 4 for g in grasps])
    order, duplicate_of = distinct_first(
        T_object_tcp, symmetry_rotations(gripper, int(diversity.symmetry)), diversity.distance,
        diversity.angle, tiers)
    return [replace(grasps[i], duplicate_of=int(d) if d else None)
            for i, d in zip(order, duplicate_of)]


def _check_ranking(rank, quality) -> None:
    """Raise InvalidInputError for a ``rank`` or ``quality`` argument of :func:`plan` it
    rejects."""
    from ..exceptions import InvalidInputError

    if rank not in ("quality", "fit"):
        raise InvalidInputError(f"rank must be 'quality' or 'fit', got {rank!r}")
    if quality is not None and not isinstance(quality, QualityConfig):
        raise InvalidInputError(f"quality must be an isf.quality.QualityConfig or None, got "
                                f"{type(quality).__name__}")


def _with_quality(grasps: list[Grasp], gripper: Gripper, obj: ObjectSurface,
                  config: QualityConfig, properties: ObjectProperties | None) -> list[Grasp]:
    """``grasps`` with the :attr:`Grasp.quality` and :attr:`Grasp.closing_obstructed_by` of each
    valid one that has no quality yet (the invalid ones keep None); ``properties``: the
    object's, or None to compute them when a grasp needs them."""
    pending = [g for g in grasps if g.valid and g.quality is None]
    if not pending:
        return grasps
    properties = object_properties(obj) if properties is None else properties
    qualities = iter(grasps_quality(gripper, obj, np.array([g.T_object_gripper for g in pending]),
                                    np.array([g.q for g in pending]), config, properties))
    return [replace(g, quality=next(qualities),
                    closing_obstructed_by=closing_obstructions(gripper, g.q, g.collision.link_depths))
            if g.valid and g.quality is None else g for g in grasps]


def _plan_quality_config(quality: QualityConfig | None, config: FitConfig) -> QualityConfig:
    """The quality parameters of a plan ranked by quality: ``quality`` (or the defaults) with
    the fit's ``contact_distance``."""
    base = QualityConfig() if quality is None else quality
    return replace(base, contact_model=replace(base.contact_model,
                                               contact_distance=config.contact_distance))


def _slots(sampler: Sampler, batch_size: int) -> int:
    """Samples to keep in flight: the batch size, or fewer when the sampler asks for it."""
    limit = sampler.in_flight_limit()
    return batch_size if limit is None else max(1, min(batch_size, int(limit)))


MAX_SAMPLES = 100_000
"""The most samples one :func:`plan` takes: its grasps (with their fit histories) stay in memory;
a larger run is many plans (``isf batch``)."""

MAX_WORKERS = 256
"""The most worker threads one :func:`plan` starts (threads beyond the machine's cores only wait)."""


def _check_arguments(samples, batch_size, workers, repair_collisions, seed=None,
                     config=None, centring=True) -> None:
    """Raise InvalidInputError for the arguments of :func:`plan` it rejects (see there)."""
    from ..exceptions import InvalidInputError

    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or seed < 0):
        raise InvalidInputError(f"seed must be None or an integer >= 0, got {seed!r}")
    if config is not None and not isinstance(config, FitConfig):
        raise InvalidInputError(f"config must be an isf.FitConfig or None, got "
                                f"{type(config).__name__}: pass isf.FitConfig(**values)")

    for name, value in (("samples", samples), ("batch_size", batch_size), ("workers", workers)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InvalidInputError(f"{name} must be a positive integer, got {value!r}")
    for name, value, limit, fix in (
            ("samples", samples, MAX_SAMPLES, "split the run into several plans (isf batch)"),
            ("workers", workers, MAX_WORKERS, "use at most one worker per core")):
        if value > limit:
            raise InvalidInputError(f"{name} must be at most {limit}, got {value}: {fix}")
    if workers > 1 and batch_size > 1:
        raise InvalidInputError(f"batch_size={batch_size} and workers={workers}: choose lockstep "
                                "batches or worker threads, not both (set one of them to 1)")
    if not isinstance(repair_collisions, (bool, RepairConfig)):
        raise InvalidInputError(
            f"repair_collisions must be True, False or an isf.RepairConfig, got "
            f"{type(repair_collisions).__name__}; pass e.g. isf.RepairConfig(iterations=10)")
    if not isinstance(centring, (bool, CentringConfig)):
        raise InvalidInputError(
            f"centring must be True, False or an isf.CentringConfig, got "
            f"{type(centring).__name__}; pass e.g. CentringConfig(error_slack=0.001)")


def plan(
    gripper: Gripper | str | Path,
    obj: ObjectSurface | Scene | str | Path | np.ndarray,
    samples: int = 60,
    sampler: str | Sampler | type[Sampler] = "regret",
    seed: int | None = 0,
    config: FitConfig | None = None,
    *,
    obstacles: Sequence[Plane] = (),
    collision_tolerance: float = 0.002,
    batch_size: int = BATCH_SIZE,
    workers: int = 1,
    repair_collisions: bool | RepairConfig = True,
    working_spacing: float | str | None = "auto",
    progress: Callable[[int, int, Grasp], None] | None = None,
    diversity: Diversity | None = DEFAULT_DIVERSITY,
    rank: str = "quality",
    quality: QualityConfig | None = None,
    centring: bool | CentringConfig = True,
) -> PlanResult:
    """Plan grasps of an object with a gripper (Algorithm 3): propose, fit, check, observe.

    The loop below is the paper's (its line numbers in the comments); ISF is :func:`isf.fit`
    (the compiled engine, checked against :func:`isf.fitting.reference.fit`, Algorithm 2, whose
    IPFO is :func:`isf.fitting.reference.ipfo`, Algorithm 1). The samples in flight run in
    lockstep in this thread or on worker threads (see the module docstring): the same loop.

    Args:
        gripper: a :class:`Gripper`, a bundled gripper name or a URDF path.
        obj: an :class:`ObjectSurface`, a mesh or point-cloud path, an (N, 3)/(N, 6) array
            (metres), or an :class:`isf.scene.Scene` (see the module docstring).
        samples: number of samples ``K_s`` to evaluate, at most 100 000 (``isf.planning.planner.MAX_SAMPLES``).
        sampler: a registered sampler name (see :func:`isf.available_samplers`), class or instance.
        seed: seed of the run's random generator; the same seed gives the same result.
        config: ISF parameters; default the paper's.
        obstacles: half-spaces the gripper must not enter (e.g. ``Plane.table(z)``), object
            frame (a scene's table is added to them).
        collision_tolerance: penetration depth tolerated before a grasp counts as colliding, metres.
        batch_size: samples fitted at once in lockstep, in one thread (see the module
            docstring); 1 is the paper's loop.
        workers: threads that fit, check and repair samples side by side (see the module
            docstring); 1 (default) plans in the calling thread; at most 256 (``isf.planning.planner.MAX_WORKERS``).
            Exclusive with ``batch_size > 1``.
        repair_collisions: when a fitted grasp collides, run
            :func:`isf.repair.clearance.repair_penetration` on it (links pushed out of the object
            and obstacles while the contact surfaces are pulled back onto the object) and keep
            the repaired grasp if the re-check finds it collision-free. Its time counts as fit
            time, its re-check as collision time. False gives the paper's Algorithm 3. A
            :class:`isf.RepairConfig` repairs with those parameters (True: the defaults,
            measured against other settings in docs/hands.md).
        progress: called after each sample as ``progress(done, total, grasp)``.
        diversity: after the ranking, grasps within this distance of a better one are marked
            ``duplicate_of`` and ranked after the distinct ones of its tier
            (:mod:`isf.planning.diversity`; default 1 cm and 30 degrees about the TCP, the
            symmetry detected); None keeps the plain ranking.
        rank: ``"quality"`` (default) ranks the valid grasps by what their contacts resist
            (:mod:`isf.quality`, computed for the valid grasps only); ``"fit"`` is the paper's
            ranking by fitting error (see the module docstring).
        quality: the contact model and metric parameters of ``rank="quality"`` (friction 0.5
            by default; its ``contact_distance`` is ``config.contact_distance``).
        centring: slide each valid grasp toward the object's centre of mass along the
            directions its fit leaves free, and keep the slid grasp when it stays
            collision-free and in contact (:mod:`isf.planning.centring`; its time counts as
            fit time). True: the default :class:`isf.CentringConfig`, or
            the parameters to use; False keeps the grasps where ISF and the repair left them
            (with ``repair_collisions=False``: the paper's Algorithm 3). Plans on a scene are
            not centred.

    Returns:
        the ranked :class:`PlanResult`.

    Raises:
        InvalidInputError: ``samples``, ``batch_size`` or ``workers`` is not a positive
            integer, ``samples`` or ``workers`` is above its limit, ``seed`` is neither None
            nor an integer >= 0, ``config`` is not a
            :class:`FitConfig`, both ``batch_size`` and ``workers`` exceed 1, ``repair_collisions`` is
            neither a bool nor a :class:`isf.RepairConfig`, ``centring`` is neither a bool
            nor a :class:`isf.CentringConfig`,
            ``working_spacing`` is neither "auto", None nor a spacing > 0, or the
            sampler proposed an invalid pose or joint vector.
        GripperDescriptionError, ObjectLoadError, SamplerNotFound: bad gripper, object or sampler.
    """
    from ..gripper.loading import load_gripper
    from ..object.loading import load_object

    started = time.perf_counter()
    _check_arguments(samples, batch_size, workers, repair_collisions, seed, config, centring)
    if diversity is not None and not isinstance(diversity, Diversity):
        from ..exceptions import InvalidInputError

        raise InvalidInputError(f"diversity must be an isf.planning.diversity.Diversity or None, "
                                f"got {type(diversity).__name__}")
    _check_ranking(rank, quality)
    config = FitConfig() if config is None else config
    gripper = gripper if isinstance(gripper, Gripper) else load_gripper(gripper)
    scene = obj if isinstance(obj, Scene) else None
    if scene is not None:
        obj, obstacles = scene.surface, (*obstacles, *scene.obstacles)
    obj = obj if isinstance(obj, ObjectSurface) else load_object(obj)
    if scene is None:
        warn_if_outside_span(gripper, obj)  # e.g. a file in mm read as metres
    obj = working_surface(obj, resolve_spacing(working_spacing, gripper))
    sampler = get_sampler(sampler)
    rng = np.random.default_rng(seed)
    sampler.reset(obj, gripper, rng)  # line 2: the sampler's state (centres, regret, trials)
    options = dict(obstacles=obstacles, tolerance=collision_tolerance, repair=repair_collisions,
                   hidden=None if scene is None else scene.unseen)
    properties = None  # the object's centre of mass and radius, computed once when needed
    if centring is not False and scene is None:
        properties = object_properties(obj)
        options.update(centring=CentringConfig() if centring is True else centring,
                       center_of_mass=properties.center_of_mass)
    settler = None if scene is None else Settler(gripper, obj, scene, config, obstacles=obstacles,
                                                 tolerance=collision_tolerance)
    quality = _plan_quality_config(quality, config) if rank == "quality" else None
    hearing = quality is not None and sampler.hears_quality()
    if hearing and properties is None:
        properties = object_properties(obj)
    heard_time = 0.0  # quality computed as outcomes arrive, for a sampler that hears it

    grasps: list[Grasp] = []

    def record(index: int, proposal: Proposal, result: FitResult, report: CollisionReport,
               repaired: bool, centred: bool) -> Outcome:
        """Keep a sample's grasp and return its outcome for the sampler."""
        nonlocal heard_time
        settled = within_bound = None
        if settler is not None:
            result, report, settled, within_bound = settler.settle(result, report)
        pieces = None if scene is None else scene.segments.touched(
            gripper, result.T_object_gripper, result.q, config.contact_distance)
        grasp = Grasp(result, report, dict(proposal.record), index, pieces, repaired, settled,
                      within_bound=within_bound, centred=centred)
        holds = None
        if hearing and grasp.valid:
            started_quality = time.perf_counter()
            (grasp,) = _with_quality([grasp], gripper, obj, quality, properties)
            holds = expected_to_hold(grasp.quality,
                                     closing_obstructed=bool(grasp.closing_obstructed_by))
            heard_time += time.perf_counter() - started_quality
        grasps.append(grasp)
        if progress is not None:
            progress(len(grasps), samples, grasp)
        touching = grasp.in_contact and grasp.one_piece
        error = result.mean_distance if touching else NO_CONTACT_ERROR
        return Outcome(proposal, error=error, collision_free=report.collision_free,
                       valid=grasp.valid, holds=holds)

    if workers == 1:
        evaluations = LockstepEvaluations(LockstepFitter(gripper, obj, config),
                                          SampleJudge(gripper, obj, config, **options), batch_size)
    else:
        evaluations = ThreadedEvaluations(
            [SampleWorker(gripper, obj, config, **options) for _ in range(workers)],
            SAMPLES_PER_WORKER * workers)
    setup_time = time.perf_counter() - started

    with evaluations:
        proposed = 0
        while len(grasps) < samples:  # line 3: K_s samples
            window = evaluations.window
            while proposed < samples and proposed - len(grasps) < _slots(sampler, window):
                (proposal,) = sampler.propose(1, rng)  # line 4: guided sampling
                evaluations.start(proposed, proposal)  # line 5: ISF, then the collision check
                proposed += 1
            outcomes = [record(*evaluated) for evaluated in evaluations.finished()]
            if outcomes:
                sampler.observe(outcomes)  # line 6: the regret update
    judges = evaluations.judges
    fit_time = evaluations.fit_time + sum(j.fit_time for j in judges)
    collision_time = sum(j.collision_time for j in judges)

    quality_started = time.perf_counter()
    if quality is not None:
        grasps = _with_quality(grasps, gripper, obj, quality, properties)
    grasps.sort(key=Grasp.sort_key)  # a tie of the quality ranking reads epsilon here
    quality_time = (time.perf_counter() - quality_started + heard_time
                    if quality is not None else 0.0)
    if diversity is not None:  # after the ranking: distinct grasps first
        diversity = replace(diversity, symmetry=diversity.order(gripper))
        grasps = _distinct_first(grasps, gripper, diversity)
    total = time.perf_counter() - started
    n_free = sum(g.collision_free for g in grasps)
    stats = PlanStats(
        samples=samples, collision_free=n_free, valid=sum(g.valid for g in grasps),
        total_time=total, time_per_collision_free=total / n_free if n_free else float("inf"),
        fit_time=fit_time, collision_time=collision_time, setup_time=setup_time,
        batch_size=int(batch_size), surface_points=obj.n_points, workers=int(workers),
        quality_time=quality_time, centring_time=sum(j.centring_time for j in judges),
    )
    repairer = judges[0].repairer  # the parameters the run repaired with, as the judges took them
    return PlanResult(tuple(grasps), stats, gripper.name, obj.name, sampler.name, seed, config,
                      None if repairer is None else repairer.config, scene, diversity, gripper,
                      rank, quality, options.get("centring"))

