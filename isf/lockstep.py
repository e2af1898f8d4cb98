"""The ISF engine: many fits advanced in lockstep (paper Algorithm 2, batched).

Every fit keeps its own state (pose, joints, pyramid level, stop rule) and follows
Algorithm 2 exactly as if it ran alone; what the fits share is the arithmetic of each
ISF iteration: one nearest-neighbour query for the contact points of all fits, one
batched IPFO (:func:`isf.ipfo.ipfo`). Fits can join at any time, and each leaves as soon
as its own stop rule fires, so a planner can keep the batch full (new samples replace
finished ones) while its sampler still learns from every finished fit.

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

import math
import time
from collections.abc import Hashable
from dataclasses import dataclass, field

import numpy as np

from .config import FitConfig
from .correspondence import Correspondences, match_many
from .exceptions import InvalidInputError
from .finger_step import FingerStepQP
from .gripper import Gripper, LinkKinematics
from .ipfo import PairBatch, ipfo
from .moment_kernels import points_in_object
from .object_surface import ObjectSurface
from .result import FitResult, FitStatus, IterationRecord
from .segments import Segments

__all__ = ["LockstepFitter", "outlier_groups", "score_fit"]


@dataclass(eq=False)
class _Fit:
    """The state of one fit between two ISF iterations."""

    key: Hashable
    T: np.ndarray
    q: np.ndarray
    qp: FingerStepQP | None
    started: float
    level: int = 0
    index: np.ndarray = field(default=None, repr=False)  # contact points of the level
    start: np.ndarray = field(default=None, repr=False)  # their positions when the level began
    current: np.ndarray = field(default=None, repr=False)
    current_normals: np.ndarray = field(default=None, repr=False)
    nearest: np.ndarray | None = field(default=None, repr=False)  # last nearest object points
    links: LinkKinematics = field(default=None, repr=False)  # kinematics at q, arrays (1, L, ...)
    max_iterations: int = 0
    eps: float = 0.0
    iteration: int = 0
    displacement: float = np.inf
    eta: float = 0.0
    status: FitStatus = FitStatus.MAX_ITERATIONS
    history: list = field(default_factory=list)

    def level_converged(self) -> bool:
        return 1.0 - self.eps <= self.eta <= 1.0 + self.eps


class LockstepFitter:
    """Runs any number of ISF fits of one gripper on one object together.

    Usage: :meth:`add` fits, call :meth:`step` until :attr:`n_active` is 0 (or keep
    adding); each call returns the fits that finished in it.

    Args:
        gripper: the gripper.
        obj: the object surface.
        config: fit parameters; default the paper's.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: FitConfig | None = None):
        self.gripper = gripper
        self.obj = obj
        self.config = FitConfig() if config is None else config
        self._levels = [np.flatnonzero(gripper.level_mask(level)) for level in range(self.config.levels)]
        self._fits: list[_Fit] = []
        self._spare_qps: list[FingerStepQP] = []

    @property
    def n_active(self) -> int:
        """Fits still running."""
        return len(self._fits)

    def add(self, key: Hashable, T_object_gripper: np.ndarray, q: np.ndarray | None = None) -> None:
        """Start a fit from palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,;
        default ``gripper.q_initial``).

        Raises:
            InvalidInputError: the pose is not a rigid transform, or ``q`` has the wrong size
                or lies outside the joint limits.
        """
        T, q = _check_pose(T_object_gripper), _check_joints(self.gripper, q)
        fit = _Fit(key, T, q, self._take_qp(), time.perf_counter())
        self._enter_level(fit, self.config.levels - 1, self.gripper.link_kinematics_many(q[None]))
        self._fits.append(fit)

    def _take_qp(self) -> FingerStepQP | None:
        """A finger-step QP for a new fit: a finished fit's (already set up) or a new one."""
        if not self.gripper.n_joints:
            return None
        if self._spare_qps:
            qp = self._spare_qps.pop()
            qp.reset()
            return qp
        return FingerStepQP(self.gripper.n_joints, self.config.finger_damping)

    def _enter_level(self, fit: _Fit, level: int, links: LinkKinematics) -> None:
        """Start pyramid level ``level``; ``links``: the fit's kinematics (leading axis of 1)."""
        fit.level, fit.links = level, links
        fit.index = self._levels[level]
        fit.max_iterations = max(1, self.config.max_iterations // 2**level)
        fit.eps = 2**level * self.config.tolerance
        (fit.current,), (fit.current_normals,) = self._level_points([fit], fit.T[None], links)
        fit.start = fit.current
        fit.nearest = None
        fit.iteration, fit.displacement, fit.eta = 0, np.inf, 0.0


    def step(self) -> list[tuple[Hashable, FitResult]]:
        """One ISF iteration of every running fit; returns ``(key, result)`` of the fits that ended."""
        fits, config = self._fits, self.config
        if not fits:
            return []
        counts = np.array([len(f.index) for f in fits])
        queries = Segments.from_counts(counts)
        point_index = np.concatenate([f.index for f in fits])
        points = np.concatenate([f.current for f in fits])
        # the last iteration's answers bound the search (exact either way)
        guess = np.concatenate([np.full(len(f.index), -1) if f.nearest is None else f.nearest for f in fits])
        nearest = self.obj.nearest(points, guess)
        for f, s in zip(fits, queries.slices()):
            f.nearest = nearest[1][s]
        normals = np.concatenate([f.current_normals for f in fits])
        pairs = _match(self.gripper, self.obj, config, points, normals, queries, point_index, nearest)
        owner = queries.ids[pairs.source]
        n_pairs = np.bincount(owner, minlength=len(fits))
        fitted = n_pairs >= config.min_pairs
        finished: list[_Fit] = []
        for f in (f for f, ok in zip(fits, fitted) if not ok):
            f.status = FitStatus.LOST_CONTACT
            finished.append(f)
        if fitted.any():
            self._iterate([f for f, ok in zip(fits, fitted) if ok], pairs, owner, fitted,
                          point_index, finished)
        done = {id(f) for f in finished}
        self._fits = [f for f in fits if id(f) not in done]
        for f in finished:
            if f.qp is not None:
                self._spare_qps.append(f.qp)
        return [(f.key, self._result(f)) for f in finished]

    def _iterate(self, fits: list[_Fit], pairs, owner, fitted, point_index, finished: list[_Fit]) -> None:
        """IPFO on the matched pairs of ``fits``, then the stop rule of each."""
        keep = fitted[owner]
        renumber = np.cumsum(fitted) - 1
        batch = PairBatch(self.gripper, Segments(renumber[owner[keep]]), point_index[pairs.source[keep]],
                          self.obj.points[pairs.target[keep]], self.obj.normals[pairs.target[keep]])
        T = np.stack([f.T for f in fits])
        q = np.stack([f.q for f in fits]).reshape(len(fits), self.gripper.n_joints)
        qps = [f.qp for f in fits] if self.gripper.n_joints else None
        links = LinkKinematics(*(np.concatenate(a) for a in zip(*(f.links for f in fits))))
        result = ipfo(batch, T, q, qps, self.config, links)
        current, current_normals = self._level_points(fits, result.T_object_gripper, result.links)
        for b, f in enumerate(fits):
            f.T, f.q = result.T_object_gripper[b], result.q[b]
            f.links = LinkKinematics(*(a[b:b + 1] for a in result.links))
            f.current, f.current_normals = current[b], current_normals[b]
            f.iteration += 1
            previous = f.displacement
            moved = (f.current - f.start).ravel()
            f.displacement = math.sqrt(moved @ moved)  # np.linalg.norm's own formula
            f.eta = 1.0 if f.displacement <= 1e-12 else f.displacement / previous
            f.history.append(IterationRecord(
                level=f.level, iteration=f.iteration, mean_distance=float(result.mean_distance[b]),
                error=float(result.error[b]), n_pairs=int(batch.segments.counts[b]), q=f.q.copy(),
                ipfo_errors=result.errors[b],
            ))
            if f.level_converged() or f.iteration >= f.max_iterations:
                if f.level == 0:
                    f.status = FitStatus.CONVERGED if f.level_converged() else FitStatus.MAX_ITERATIONS
                    finished.append(f)
                else:
                    self._enter_level(f, f.level - 1, f.links)

    def _level_points(self, fits: list[_Fit], T: np.ndarray, links: LinkKinematics):
        """Each fit's level points and normals at its new state, object frame: lists of (k_b, 3)."""
        g = self.gripper
        index = np.concatenate([f.index for f in fits])
        seg = Segments.from_counts(np.array([len(f.index) for f in fits]))
        points, normals = points_in_object(T, links.rotations, links.positions, seg.ids, g.point_link[index],
                                           g.points_link[index], g.normals_link[index])
        slices = seg.slices()
        return [points[s] for s in slices], [normals[s] for s in slices]

    def _result(self, f: _Fit) -> FitResult:
        """Score the final state on the finest level with fresh correspondences."""
        return score_fit(self.gripper, self.obj, f.T, f.q, self.config, f.status,
                         tuple(f.history), time.perf_counter() - f.started)


def _match(gripper: Gripper, obj: ObjectSurface, config: FitConfig, points: np.ndarray,
           normals: np.ndarray, fits: Segments, point_index: np.ndarray,
           nearest: tuple[np.ndarray, np.ndarray] | None = None) -> Correspondences:
    """:func:`match_many` with the filters of ``config`` (``point_index``: gripper point of each query)."""
    return match_many(
        obj, points, fits, nearest=nearest,
        outlier_groups=outlier_groups(gripper, fits, point_index, config),
        outlier_factor=config.outlier_factor, outlier_floor=config.outlier_floor,
        reject_duplicates=config.reject_duplicates, normals=normals, max_normal_angle=config.max_normal_angle,
    )


def outlier_groups(gripper: Gripper, fits: Segments, point_index: np.ndarray,
                   config: FitConfig) -> Segments | None:
    """The groups whose median sets the outlier threshold: each fit's points of one contact
    surface (``config.outlier_scope == "surface"``), or None (whole fits).

    Args:
        gripper: the gripper.
        fits: the fit of each query point (points grouped by fit).
        point_index: gripper point index of each query point, (M,), ascending within a fit.
    """
    if config.outlier_scope == "fit":
        return None
    return Segments.runs(gripper.point_surface[point_index], fits.ids)


def score_fit(gripper: Gripper, obj: ObjectSurface, T: np.ndarray, q: np.ndarray, config: FitConfig,
              status: FitStatus, history: tuple[IterationRecord, ...], elapsed: float) -> FitResult:
    """The :class:`FitResult` of a final state ``(T, q)``: all contact points matched afresh."""
    points, normals = gripper.contact_points(q)
    R, t = T[:3, :3], T[:3, 3]
    points = points @ R.T + t
    normals = normals @ R.T
    nearest = obj.nearest(points)
    pairs = _match(gripper, obj, config, points, normals, Segments.single(len(points)),
                   np.arange(len(points)), nearest)
    if len(pairs.source):
        batch = PairBatch(gripper, Segments.single(len(pairs.source)), pairs.source,
                          obj.points[pairs.target], obj.normals[pairs.target])
        state = batch.evaluate(gripper.link_kinematics_many(q[None]))
        d, c = batch.residuals(T[None], *state[:2])  # c = (R n^p)^T n^q + 1
        mean_distance = float(np.abs(d).mean())
        misalignment = float(np.arccos(np.clip(1.0 - c, -1.0, 1.0)).mean())
        error = float(batch.errors(T[None], *state[:2], config.normal_weight)[0])
    else:
        mean_distance = misalignment = error = float("inf")
    touching = nearest[0] <= config.contact_distance
    surface_contact = {
        s.name: float(touching[gripper.point_surface == k].mean())
        for k, s in enumerate(gripper.surfaces)
    }
    return FitResult(
        T_object_gripper=T, q=q.copy(), joints=gripper.joints(q), mean_distance=mean_distance,
        normal_misalignment=misalignment, error=error, n_pairs=len(pairs.source),
        contact_points=points[pairs.source], object_points=obj.points[pairs.target],
        surface_contact=surface_contact, iterations=len(history), status=status,
        history=history, time=elapsed,
    )


def _check_pose(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidInputError(
            f"T_object_gripper must be a finite 4x4 matrix, got shape {T.shape}: "
            "pass a homogeneous transform"
        )
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0.0 or not np.allclose(
        T[3], [0.0, 0.0, 0.0, 1.0]
    ):
        raise InvalidInputError(
            "T_object_gripper is not a rigid transform (its 3x3 block must be a rotation "
            "and its last row [0, 0, 0, 1]): orthonormalise it first"
        )
    return T.copy()


def _check_joints(gripper: Gripper, q: np.ndarray | None) -> np.ndarray:
    if q is None:
        return gripper.q_initial.copy()
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (gripper.n_joints,) or not np.all(np.isfinite(q)):
        raise InvalidInputError(
            f"q must hold {gripper.n_joints} finite values, one per actuated joint "
            f"{list(gripper.joint_names)}, got {q.shape[0]}"
        )
    outside = [
        f"{name}={value:g} not in [{lo:g}, {hi:g}]"
        for name, value, lo, hi in zip(gripper.joint_names, q, gripper.lower, gripper.upper)
        if not lo - 1e-12 <= value <= hi + 1e-12
    ]
    if outside:
        raise InvalidInputError(f"initial joints outside their limits: {', '.join(outside)}")
    return gripper.clip(q)
