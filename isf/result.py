"""Results of a fit: :class:`FitResult`, its per-iteration :class:`IterationRecord` and their
:class:`History`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

__all__ = ["FitResult", "FitStatus", "History", "IterationRecord"]


class FitStatus(str, Enum):
    """Why a fit stopped."""

    CONVERGED = "converged"
    """The stop rule of Algorithm 2 fired on the finest level."""
    MAX_ITERATIONS = "max_iterations"
    """The finest level reached its iteration cap ``I0``."""
    LOST_CONTACT = "lost_contact"
    """Fewer than ``min_pairs`` contact points matched the object."""


@dataclass(frozen=True)
class IterationRecord:
    """One entry of a fit's :class:`History`: its start (iteration 0) or one ISF iteration (one
    correspondence search plus one IPFO run).

    Attributes:
        level: pyramid level (``L-1`` coarsest ... 0 finest); the start is on ``L-1``.
        iteration: iteration number within the level, from 1; 0 for the start.
        mean_distance: mean absolute point-to-plane distance of the iteration's matched pairs
            after IPFO (at the start: of the pairs matched at the start pose, before IPFO),
            metres.
        error: fitting error E of those pairs summed over them (eq. 9a), after IPFO (at the
            start: before it), m^2; :attr:`error_per_pair` is E per pair.
        n_pairs: matched pairs used.
        q: joint vector after the iteration (at the start: the initial joints), (n_joints,),
            metres or radians: the finger displacement of Fig. 5.
        T_object_gripper: palm pose (gripper frame, the URDF root link, in the object frame)
            after the iteration (at the start: the initial pose), (4, 4), metres.
        displacement_ratio: the stop rule's ``eta = e_s / e_s,prev`` after the iteration
            (:mod:`isf.fitting.engine`): 0 on a level's first iteration (no previous
            displacement), 1 when the contact points did not move, NaN at the start.
        ipfo_errors: E after each IPFO alternation of the iteration, m^2 (Fig. 5b); empty at
            the start.
    """

    level: int
    iteration: int
    mean_distance: float
    error: float
    n_pairs: int
    q: np.ndarray
    T_object_gripper: np.ndarray
    displacement_ratio: float
    ipfo_errors: tuple[float, ...]

    @property
    def error_per_pair(self) -> float:
        """E divided by the pairs it sums over, in m^2, comparable across iterations whose pair
        counts differ (NaN without pairs)."""
        return self.error / self.n_pairs if self.n_pairs else float("nan")


class History(Sequence):
    """A fit's :class:`IterationRecord` list: the start pose (iteration 0) then each ISF
    iteration, in order (``len(history) == fit.iterations + 1``; empty when the fit lost contact
    at its start pose). A read-only sequence kept as arrays and turned into records when first
    read (a plan makes thousands of records that nobody reads); each record's field is also
    available for all records at once as an array attribute of the same name.

    A fit the planner's collision repair moved (:attr:`isf.Grasp.repaired`) keeps the history of
    the fit it repaired, which ends before the repair.

    Attributes:
        level, iteration: per record (H,), int64.
        mean_distance: per record (H,), metres.
        error: E summed over the pairs, per record (H,), m^2 (:attr:`error_per_pair`: per
            pair).
        n_pairs: per record (H,), int64.
        q: joints after each record, (H, n_joints).
        T_object_gripper: palm pose after each record, (H, 4, 4).
        displacement_ratio: the stop rule's ``eta`` per record (H,) (NaN at the start).
        ipfo_errors: IPFO's errors per record (H, I), of which the first ``n_ipfo`` (H,) of
            each row count (:attr:`IterationRecord.ipfo_errors` holds just those).
        n_ipfo: per record (H,), int64.
    """

    def __init__(self, *, level: np.ndarray, iteration: np.ndarray, mean_distance: np.ndarray,
                 error: np.ndarray, n_pairs: np.ndarray, q: np.ndarray,
                 T_object_gripper: np.ndarray, displacement_ratio: np.ndarray,
                 ipfo_errors: np.ndarray, n_ipfo: np.ndarray):
        self.level, self.iteration, self.n_pairs, self.n_ipfo = level, iteration, n_pairs, n_ipfo
        self.mean_distance, self.error, self.q = mean_distance, error, q
        self.T_object_gripper, self.displacement_ratio = T_object_gripper, displacement_ratio
        self.ipfo_errors = ipfo_errors
        self._records: tuple[IterationRecord, ...] | None = None

    @classmethod
    def from_records(cls, records: Sequence[IterationRecord], n_joints: int) -> History:
        """The history of ``records`` (of a gripper with ``n_joints`` joints)."""
        width = max((len(r.ipfo_errors) for r in records), default=0)
        ipfo = np.zeros((len(records), width))
        for h, record in enumerate(records):
            ipfo[h, :len(record.ipfo_errors)] = record.ipfo_errors
        return cls(
            level=np.array([r.level for r in records], np.int64),
            iteration=np.array([r.iteration for r in records], np.int64),
            mean_distance=np.array([r.mean_distance for r in records], float),
            error=np.array([r.error for r in records], float),
            n_pairs=np.array([r.n_pairs for r in records], np.int64),
            q=np.array([r.q for r in records], float).reshape(len(records), n_joints),
            T_object_gripper=np.array([r.T_object_gripper for r in records],
                                      float).reshape(len(records), 4, 4),
            displacement_ratio=np.array([r.displacement_ratio for r in records], float),
            ipfo_errors=ipfo, n_ipfo=np.array([len(r.ipfo_errors) for r in records], np.int64))

    @property
    def error_per_pair(self) -> np.ndarray:
        """E per pair of each record, (H,), m^2 (NaN without pairs)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.n_pairs > 0, self.error / np.maximum(self.n_pairs, 1), np.nan)

    def _built(self) -> tuple[IterationRecord, ...]:
        if self._records is None:
            columns = (self.level, self.iteration, self.mean_distance, self.error, self.n_pairs,
                       self.displacement_ratio, self.n_ipfo, self.ipfo_errors)
            level, iteration, distance, error, pairs, ratio, n_ipfo, ipfo = (
                a.tolist() for a in columns)
            self._records = tuple(
                IterationRecord(level=level[h], iteration=iteration[h], mean_distance=distance[h],
                                error=error[h], n_pairs=pairs[h], q=self.q[h],
                                T_object_gripper=self.T_object_gripper[h],
                                displacement_ratio=ratio[h],
                                ipfo_errors=tuple(ipfo[h][:n_ipfo[h]]))
                for h in range(len(level)))
        return self._records

    def __len__(self) -> int:
        return len(self.level)

    def __getitem__(self, index):
        return self._built()[index]

    def __iter__(self):
        return iter(self._built())

    def __repr__(self) -> str:
        return f"History({len(self)} records: the start and {max(0, len(self) - 1)} iterations)"


@dataclass(frozen=True, eq=False)
class FitResult:
    """The outcome of :func:`isf.fit`.

    Attributes:
        T_object_gripper: final pose of the gripper frame (URDF root link) in the object frame, (4, 4).
        q: final joint vector, (n_joints,), metres or radians.
        joints: the same, by joint name.
        mean_distance: mean absolute point-to-plane distance of the final matched pairs,
            metres (lower is better).
        normal_misalignment: mean angle between each contact normal and the reversed
            object normal, radians (0 = faces flush).
        error: total fitting error E of the final pairs, summed over them, m^2 (eq. 9a);
            :attr:`error_per_pair` is E per pair.
        n_pairs: final matched pairs.
        contact_points: matched contact points in the object frame, (K, 3), metres.
        object_points: their matched object points, (K, 3), metres.
        surface_contact: per contact surface, the fraction of its points within
            ``contact_distance`` of the object.
        iterations: ISF iterations over all levels.
        status: why the fit stopped.
        history: the :class:`History`: the start pose (iteration 0), then one
            :class:`IterationRecord` per ISF iteration (palm pose, joints, distance, E, the stop
            rule's displacement ratio). A grasp the planner repaired (:attr:`isf.Grasp.repaired`)
            keeps the history of the fit it repaired, which ends before the repair moved it:
            its last record is not the grasp's pose.
        time: wall time from the start to the end of the fit, seconds (fits run together by
            :func:`isf.fit_many` or :func:`isf.plan` share that time with each other).
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    joints: dict[str, float]
    mean_distance: float
    normal_misalignment: float
    error: float
    n_pairs: int
    contact_points: np.ndarray
    object_points: np.ndarray
    surface_contact: dict[str, float]
    iterations: int
    status: FitStatus
    history: History
    time: float

    @property
    def converged(self) -> bool:
        """True when the stop rule fired (status ``converged``)."""
        return self.status is FitStatus.CONVERGED

    @property
    def error_per_pair(self) -> float:
        """:attr:`error` divided by :attr:`n_pairs`, m^2 (NaN without pairs)."""
        return self.error / self.n_pairs if self.n_pairs else float("nan")

    @property
    def all_surfaces_in_contact(self) -> bool:
        """True when every contact surface has at least one point in contact."""
        return all(v > 0.0 for v in self.surface_contact.values())

    def __repr__(self) -> str:
        return (
            f"FitResult(status={self.status.value}, mean_distance={self.mean_distance * 1e3:.3f} mm, "
            f"n_pairs={self.n_pairs}, iterations={self.iterations}, joints={self.joints})"
        )
