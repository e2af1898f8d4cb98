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
    """One ISF iteration (one correspondence search plus one IPFO run).

    Attributes:
        level: pyramid level (``L-1`` coarsest ... 0 finest).
        iteration: iteration number within the level, from 1.
        mean_distance: mean point-to-plane distance of the matched pairs after IPFO, metres.
        error: total fitting error E after IPFO, m^2.
        n_pairs: matched pairs used.
        q: joint vector after IPFO, (n_joints,): the finger displacement of Fig. 5.
        ipfo_errors: E after each IPFO alternation, m^2 (Fig. 5b).
    """

    level: int
    iteration: int
    mean_distance: float
    error: float
    n_pairs: int
    q: np.ndarray
    ipfo_errors: tuple[float, ...]


class History(Sequence):
    """The :class:`IterationRecord` of each ISF iteration of a fit, in order: a read-only
    sequence kept as arrays and turned into records when first read (a plan makes thousands
    of records that nobody reads).

    Args:
        level, iteration: per iteration (H,), integers.
        mean_distance, error: per iteration (H,), metres and m^2.
        n_pairs: per iteration (H,), integers.
        q: joint vector after each iteration (H, n_joints).
        ipfo_errors: IPFO's errors per iteration (H, I), of which the first ``n_ipfo`` (H,)
            of each row count.
    """

    def __init__(self, level: np.ndarray, iteration: np.ndarray, mean_distance: np.ndarray,
                 error: np.ndarray, n_pairs: np.ndarray, q: np.ndarray, ipfo_errors: np.ndarray,
                 n_ipfo: np.ndarray):
        self._arrays = (level, iteration, mean_distance, error, n_pairs, q, ipfo_errors, n_ipfo)
        self._length = len(level)
        self._records: tuple[IterationRecord, ...] | None = None

    def _built(self) -> tuple[IterationRecord, ...]:
        if self._records is None:
            level, iteration, distance, error, pairs, q, ipfo, n_ipfo = self._arrays
            level, iteration, distance, error, pairs, n_ipfo, ipfo = (
                a.tolist() for a in (level, iteration, distance, error, pairs, n_ipfo, ipfo))
            self._records = tuple(
                IterationRecord(level=level[h], iteration=iteration[h], mean_distance=distance[h],
                                error=error[h], n_pairs=pairs[h], q=q[h],
                                ipfo_errors=tuple(ipfo[h][:n_ipfo[h]]))
                for h in range(self._length))
        return self._records

    def __len__(self) -> int:
        return self._length

    def __getitem__(self, index):
        return self._built()[index]

    def __iter__(self):
        return iter(self._built())

    def __repr__(self) -> str:
        return f"History({self._length} iterations)"


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
        error: total fitting error E of the final pairs, m^2 (eq. 9a).
        n_pairs: final matched pairs.
        contact_points: matched contact points in the object frame, (K, 3), metres.
        object_points: their matched object points, (K, 3), metres.
        surface_contact: per contact surface, the fraction of its points within
            ``contact_distance`` of the object.
        iterations: ISF iterations over all levels.
        status: why the fit stopped.
        history: one record per ISF iteration. A grasp the planner repaired
            (:attr:`isf.Grasp.repaired`) keeps the history of the fit it repaired, which ends
            before the repair moved it.
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
    history: Sequence[IterationRecord]
    time: float

    @property
    def converged(self) -> bool:
        """True when the stop rule fired (status ``converged``)."""
        return self.status is FitStatus.CONVERGED

    @property
    def all_surfaces_in_contact(self) -> bool:
        """True when every contact surface has at least one point in contact."""
        return all(v > 0.0 for v in self.surface_contact.values())

    def __repr__(self) -> str:
        return (
            f"FitResult(status={self.status.value}, mean_distance={self.mean_distance * 1e3:.3f} mm, "
            f"n_pairs={self.n_pairs}, iterations={self.iterations}, joints={self.joints})"
        )
