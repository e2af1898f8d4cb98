"""The ISF engine: many fits advanced in lockstep (paper Algorithm 2, batched).

Every fit keeps its own state (pose, joints, pyramid level, stop rule) and follows
Algorithm 2 exactly as if it ran alone; what the fits share is the work of each ISF
iteration, done for all of them in compiled code (:mod:`isf.fitting.engine_kernel`): the
correspondences, IPFO (:mod:`isf.fitting._ipfo_kernel`) and the stop rules. Fits can join at any
time, and each leaves as soon as its own stop rule fires, so a planner can keep the batch
full (new samples replace finished ones) while its sampler still learns from every finished
fit. Python sees a fit when it starts and when it ends (and when IPFO needs OSQP or Pinocchio,
:func:`isf.fitting._ipfo.answer_requests`).

The stop rule
-------------
On pyramid level ``l`` the loop keeps ``e_s = ||S^f - S^f_0||``, the
displacement of the level's contact points from where they stood when the level
began (cumulative, Frobenius norm over the points), and ``eta = e_s / e_s,prev``.
It stops when ``eta`` lies in ``[1 - eps_l, 1 + eps_l]`` with ``eps_l = 2**l eps0``
(the total displacement stopped growing by more than ``eps_l`` relatively), or
after ``I_l = I0 / 2**l`` iterations. A gripper that does not move at all
(``e_s = 0``) has converged too.
"""

from __future__ import annotations

import time
from collections.abc import Hashable, Sequence
from typing import NamedTuple

import numpy as np

from ..config import FitConfig
from ..exceptions import InvalidInputError, JointLimitError, JointLimitViolation
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..result import FitResult, FitStatus, History, IterationRecord
from . import engine_kernel as kernel
from ._finger_step import FingerStepQP
from ._ipfo import answer_requests, ipfo_parameters

__all__ = ["LockstepFitter", "PoseScore", "PoseScorer", "fit_parameters", "gripper_arrays",
           "score_fit"]

_STATUS = {kernel.CONVERGED: FitStatus.CONVERGED, kernel.MAX_ITERATIONS: FitStatus.MAX_ITERATIONS,
           kernel.LOST_CONTACT: FitStatus.LOST_CONTACT}


class LockstepFitter:
    """Runs any number of ISF fits of one gripper on one object together.

    Usage: :meth:`add` fits, then call :meth:`advance` (or :meth:`step`) until
    :attr:`n_active` is 0, or keep adding; each call returns the fits that finished in it.

    Args:
        gripper: the gripper.
        obj: the object surface.
        config: fit parameters; default the paper's.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig | None = None):
        self.gripper = gripper
        self.obj = obj
        self.config = FitConfig() if config is None else config
        self._grip = gripper_arrays(gripper, self.config.levels)
        self._obj = kernel.ObjectArrays(obj.points, obj.normals, obj.search.tree)
        self._fit_params = fit_parameters(self.config)
        self._ipfo_params = ipfo_parameters(gripper, self.config)
        self._history_length = 1 + sum(max(1, self.config.max_iterations // 2**level)
                                       for level in range(self.config.levels))
        self._keys: list[Hashable] = []
        self._started: list[float] = []
        self._qps: list[FingerStepQP | None] = []
        self._slots, self._history = self._allocate(0)

    @property
    def n_active(self) -> int:
        """Fits still running."""
        return int(np.count_nonzero(self._slots.status == kernel.RUNNING))

    def add(self, key: Hashable, T_object_gripper: np.ndarray, q: np.ndarray | None = None) -> None:
        """Start a fit from palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,;
        default ``gripper.q_initial``).

        Raises:
            InvalidInputError: the pose is not a rigid transform, or ``q`` has the wrong size
                or lies outside the joint limits.
        """
        T, q = _check_pose(T_object_gripper), _check_joints(self.gripper, q)
        free = np.flatnonzero(self._slots.status == kernel.EMPTY)
        b = int(free[0]) if len(free) else self._grow()
        slots = self._slots
        slots.T[b], slots.q[b] = T, q
        links = self.gripper.link_kinematics_many(q[None])
        slots.R[b], slots.p[b] = links.rotations[0], links.positions[0]
        slots.Jv[b], slots.Jw[b] = links.J_linear[0], links.J_angular[0]
        slots.status[b] = kernel.RUNNING
        slots.last[b] = -1  # no nearest object points yet
        self._history.count[b] = 0
        kernel.enter_level(b, self.config.levels - 1, slots, self._grip)
        self._keys[b], self._started[b] = key, time.perf_counter()
        if self._qps[b] is not None:
            self._qps[b].reset()

    def step(self) -> list[tuple[Hashable, FitResult]]:
        """One ISF iteration of every running fit; returns ``(key, result)`` of the fits that
        ended."""
        return self._run(1)

    def advance(self) -> list[tuple[Hashable, FitResult]]:
        """ISF iterations of every running fit until at least one ends (or none runs); returns
        ``(key, result)`` of the fits that ended in the last iteration."""
        return self._run(None)

    def _run(self, max_rounds: int | None) -> list[tuple[Hashable, FitResult]]:
        left = np.iinfo(np.int64).max if max_rounds is None else max_rounds
        slots, history, grip, fit_params = self._slots, self._history, self._grip, self._fit_params
        while left > 0:
            outcome = kernel.run(slots, history, grip, self._obj, fit_params, self._ipfo_params,
                                 left)
            if outcome.reason != kernel.PENDING:
                break
            # IPFO of this round needs Python: finish it, then the round
            fits = outcome.pairs.fits.tolist()
            qps = [self._qp(b) for b in fits] if self.gripper.n_joints else None
            answer_requests(self.gripper, qps, outcome.state, outcome.moments, self._ipfo_params,
                            outcome.request)
            kernel.finish_round(slots, history, grip, fit_params, outcome.pairs, outcome.state)
            left -= outcome.rounds + 1
            if np.any(slots.status > kernel.RUNNING):
                break
        ended = np.flatnonzero(slots.status > kernel.RUNNING).tolist()
        return [(self._keys[b], self._result(b)) for b in ended]

    def _qp(self, b: int) -> FingerStepQP:
        """Slot ``b``'s finger-step QP (OSQP, set up on first use)."""
        if self._qps[b] is None:
            self._qps[b] = FingerStepQP(self.gripper.n_joints, self.config.finger_damping)
        return self._qps[b]

    def _result(self, b: int) -> FitResult:
        """The finished fit of slot ``b`` scored on its final state; the slot is freed."""
        slots = self._slots
        T, q, R, p, last = slots.T[b], slots.q[b], slots.R[b], slots.p[b], slots.last[b]
        status = _STATUS[int(slots.status[b])]
        slots.status[b] = kernel.EMPTY
        elapsed = time.perf_counter() - self._started[b]
        return _scored(self.gripper, self.obj, self.config, self._grip, T.copy(), q.copy(), R, p,
                       last, status, self._records(b), elapsed)

    def _records(self, b: int) -> History:
        h = self._history
        count = int(h.count[b])
        return History(**{name: array[b, :count].copy() for name, array in (
            ("level", h.level), ("iteration", h.iteration), ("mean_distance", h.mean_distance),
            ("error", h.error), ("n_pairs", h.n_pairs), ("q", h.q), ("T_object_gripper", h.T),
            ("displacement_ratio", h.eta), ("ipfo_errors", h.ipfo_errors), ("n_ipfo", h.n_ipfo))})

    def _allocate(self, n_slots: int) -> tuple[kernel.Slots, kernel.HistoryArrays]:
        """Empty slot and history arrays for ``n_slots`` fits."""
        g, S = self.gripper, n_slots
        n, L, P = g.n_joints, len(g.contact_links), g.n_points
        H, n_ipfo = self._history_length, self.config.max_ipfo_iterations
        slots = kernel.Slots(
            T=np.zeros((S, 4, 4)), q=np.zeros((S, n)), R=np.zeros((S, L, 3, 3)),
            p=np.zeros((S, L, 3)), Jv=np.zeros((S, L, 3, n)), Jw=np.zeros((S, L, 3, n)),
            status=np.full(S, kernel.EMPTY, np.int64), level=np.zeros(S, np.int64),
            iteration=np.zeros(S, np.int64), displacement=np.zeros(S), eta=np.zeros(S),
            current=np.zeros((S, P, 3)), current_normals=np.zeros((S, P, 3)),
            start=np.zeros((S, P, 3)), last=np.full((S, P), -1, np.int64))
        history = kernel.HistoryArrays(
            level=np.zeros((S, H), np.int64), iteration=np.zeros((S, H), np.int64),
            mean_distance=np.zeros((S, H)), error=np.zeros((S, H)),
            n_pairs=np.zeros((S, H), np.int64), q=np.zeros((S, H, n)),
            ipfo_errors=np.zeros((S, H, n_ipfo)), n_ipfo=np.zeros((S, H), np.int64),
            count=np.zeros(S, np.int64), T=np.zeros((S, H, 4, 4)), eta=np.zeros((S, H)))
        return slots, history

    def _grow(self) -> int:
        """Double the slots (at least 8); returns the first new one."""
        old = len(self._keys)
        slots, history = self._allocate(max(8, 2 * old))
        for new, current in zip(slots + history, self._slots + self._history):
            new[:old] = current
        self._slots, self._history = slots, history
        extra = len(slots.status) - old
        self._keys += [None] * extra
        self._started += [0.0] * extra
        self._qps += [None] * extra
        return old


def gripper_arrays(gripper: Gripper, levels: int) -> kernel.GripperArrays:
    """The gripper's contact points for :func:`isf.fitting.engine_kernel.run`, with ``levels``
    pyramid levels."""
    P = gripper.n_points
    level_rows = np.zeros((levels, P), np.int64)
    level_count = np.zeros(levels, np.int64)
    for level in range(levels):
        rows = np.flatnonzero(gripper.level_mask(level))
        level_rows[level, :len(rows)], level_count[level] = rows, len(rows)
    return kernel.GripperArrays(
        points_link=gripper.points_link, normals_link=gripper.normals_link,
        point_link=gripper.point_link.astype(np.int64),
        point_surface=gripper.point_surface.astype(np.int64), level_rows=level_rows,
        level_count=level_count)


def fit_parameters(config: FitConfig) -> kernel.FitParameters:
    """The parameters of :func:`isf.fitting.engine_kernel.run` read from ``config``."""
    return kernel.FitParameters(
        levels=int(config.levels), max_iterations=int(config.max_iterations),
        tolerance=float(config.tolerance), outlier_factor=float(config.outlier_factor),
        outlier_floor=float(config.outlier_floor),
        per_surface=config.outlier_scope == "surface",
        reject_duplicates=bool(config.reject_duplicates),
        check_normals=bool(config.max_normal_angle < np.pi),
        cos_limit=float(-np.cos(config.max_normal_angle)), min_pairs=int(config.min_pairs),
        contact_distance=float(config.contact_distance))


def score_fit(gripper: Gripper, obj: ObjectSurface, T: np.ndarray, q: np.ndarray, config: FitConfig,
              status: FitStatus, history: Sequence[IterationRecord], elapsed: float) -> FitResult:
    """The :class:`FitResult` of a final state ``(T, q)``: all contact points matched afresh."""
    links = gripper.link_kinematics(q)
    last = np.full(gripper.n_points, -1, np.int64)
    T, q = np.array(T, dtype=float), np.array(q, dtype=float)
    return _scored(gripper, obj, config, gripper_arrays(gripper, 1), T, q, links.rotations,
                   links.positions, last, status, history, elapsed)


class PoseScore(NamedTuple):
    """What :class:`PoseScorer` returns for a pose: the two figures a :class:`FitResult` of it
    would give.

    Attributes:
        mean_distance: mean absolute point-to-plane distance of the matched pairs, m (inf: none).
        surface_contact: per contact surface (in ``Gripper.surfaces`` order), the fraction of
            its points within ``contact_distance`` of the object, (S,).
    """

    mean_distance: float
    surface_contact: np.ndarray


class PoseScorer:
    """Scores many palm poses of a gripper at fixed joints on one object as :func:`score_fit`
    does (every contact point matched afresh), with the set-up done once and no
    :class:`FitResult` built: for searches that try many poses and keep one.

    Args:
        gripper, obj, config: the gripper, the object surface and the fit parameters.
        q: the joints, (n_joints,).
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig, q: np.ndarray):
        links = gripper.link_kinematics(np.asarray(q, dtype=float))
        self._links = (links.rotations, links.positions)
        self._grip = gripper_arrays(gripper, 1)
        self._object = kernel.ObjectArrays(obj.points, obj.normals, obj.search.tree)
        self._parameters = fit_parameters(config)
        self._alpha = float(config.normal_weight)
        self._last = np.full(gripper.n_points, -1, np.int64)
        self._surface = gripper.point_surface
        self._counts = np.bincount(self._surface, minlength=len(gripper.surfaces))

    def __call__(self, T_object_gripper: np.ndarray) -> PoseScore:
        """The score of palm pose ``T_object_gripper`` (4, 4), object frame."""
        score = kernel.score_state(np.asarray(T_object_gripper, dtype=float), *self._links,
                                   self._grip, self._object, self._parameters, self._alpha,
                                   self._last)
        touching = np.bincount(self._surface, weights=score.touching, minlength=len(self._counts))
        return PoseScore(float(score.mean_distance), touching / self._counts)


def _scored(gripper: Gripper, obj: ObjectSurface, config: FitConfig, grip: kernel.GripperArrays,
            T: np.ndarray, q: np.ndarray, R: np.ndarray, p: np.ndarray, last: np.ndarray,
            status: FitStatus, history: Sequence[IterationRecord], elapsed: float) -> FitResult:
    """:func:`isf.fitting.engine_kernel.score_state` of a state as a :class:`FitResult` (``grip``:
    :func:`gripper_arrays`; ``last``: each contact point's last nearest object point, (P,),
    -1 for none)."""
    score = kernel.score_state(
        T, R, p, grip, kernel.ObjectArrays(obj.points, obj.normals, obj.search.tree),
        fit_parameters(config), float(config.normal_weight), last)
    surface_contact = {s.name: float(score.touching[gripper.point_surface == k].mean())
                       for k, s in enumerate(gripper.surfaces)}
    return FitResult(
        T_object_gripper=T, q=q, joints=gripper.joints(q), mean_distance=float(score.mean_distance),
        normal_misalignment=float(score.misalignment), error=float(score.error),
        n_pairs=len(score.rows), contact_points=score.points[score.rows],
        object_points=obj.points[score.targets],
        surface_contact=surface_contact,
        iterations=max(0, len(history) - 1), status=status, history=history, time=elapsed,
    )


def _check_pose(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidInputError(
            f"T_object_gripper must be a finite 4x4 matrix, got shape {T.shape}: "
            "pass a homogeneous transform"
        )
    R = T[:3, :3]
    identity = np.eye(3)
    # np.allclose's tests (|a - b| <= atol + 1e-5 |b|) written out, without allclose's overhead
    orthonormal = np.all(np.abs(R.T @ R - identity) <= 1e-6 + 1e-5 * identity)
    last = np.array([0.0, 0.0, 0.0, 1.0])
    homogeneous = np.abs(T[3] - last) <= 1e-8 + 1e-5 * last
    last_row = np.all(homogeneous)
    if not orthonormal or np.linalg.det(R) < 0.0 or not last_row:
        raise InvalidInputError(
            "T_object_gripper is not a rigid transform (its 3x3 block must be a rotation "
            "and its last row [0, 0, 0, 1]): orthonormalise it first"
        )
    return T.copy()


def _check_joints(gripper: Gripper, q: np.ndarray | None) -> np.ndarray:
    if q is None:
        return gripper.q_initial.copy()
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (gripper.n_joints,):
        raise InvalidInputError(
            f"q must hold {gripper.n_joints} finite values, one per actuated joint "
            f"{list(gripper.joint_names)}, got {q.shape[0]}"
        )
    if not np.all(np.isfinite(q)):
        raise InvalidInputError(
            f"q holds NaN, infinite or missing (None) values: {q.tolist()}; give finite joint "
            f"values for {list(gripper.joint_names)} (radians or metres), or q=None for the "
            "gripper's initial joints"
        )
    outside = [
        JointLimitViolation(name, float(value), float(lo), float(hi))
        for name, value, lo, hi in zip(gripper.joint_names, q, gripper.lower, gripper.upper)
        if not lo - 1e-12 <= value <= hi + 1e-12
    ]
    if outside:
        raise JointLimitError(outside, "initial joints")
    return gripper.clip(q)
