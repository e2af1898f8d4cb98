"""Algorithm 1 (IPFO) of B fits as one compiled loop, paused for what only Python can do.

:func:`alternate` runs the alternations of every fit (palm step, finger step, kinematics,
the error test that keeps or undoes the alternation, the stop rule) with the kernels of
:mod:`isf.fitting.moment_kernels`, :mod:`isf.fitting._box_qp` and :mod:`isf.gripper.chain`.
Two things it cannot do itself; for them it returns a request and is resumed at the same
alternation with the answer (:func:`isf.fitting._ipfo.answer_requests` drives it):

* ``NEED_FINGER_STEP``: a multi-joint finger QP the active set could not certify (it
  goes to OSQP);
* ``NEED_KINEMATICS``: a gripper whose joints :mod:`isf.gripper.chain` does not cover (Pinocchio).

An alternation is recomputed from its start when resumed (the same numbers: every step is
deterministic); the given answer replaces only the part that was asked for.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.arrays import copy_into
from ..compiled.kernels import kernel
from ..gripper.chain import ChainArrays, compiled_frame_kinematics
from ._finger_step import bounded_steps
from .moment_kernels import GroupMoments, finger_systems, fit_errors, palm_updates

__all__ = ["DONE", "IPFOAnswer", "IPFOMoments", "IPFOParameters", "IPFORequest", "IPFOState",
           "NEED_FINGER_STEP", "NEED_KINEMATICS", "alternate", "no_answer"]

DONE, NEED_FINGER_STEP, NEED_KINEMATICS = 0, 1, 2
"""IPFO's status, finished or the request it paused with."""


class IPFOState(NamedTuple):
    """The state of B fits during IPFO, updated in place (n joints, L contact links).

    Attributes:
        T: palm poses ``T_object_gripper``, (B, 4, 4) float64.
        q: joints, (B, n) float64 (rad or m).
        R: contact-link rotations ``R_gripper_link``, (B, L, 3, 3) float64.
        p: contact-link origins in the gripper frame, (B, L, 3) float64, m.
        Jv: Jacobians of the link origins, (B, L, 3, n) float64.
        Jw: angular Jacobians of the links, (B, L, 3, n) float64.
        error: the fitting error E, (B,) float64, m^2.
        active: which fits still alternate, (B,) bool.
        log: E after each kept alternation, (B, I) float64, m^2; row ``b`` holds ``n_log[b]``.
        n_log: entries of each row of ``log``, (B,) int64.
    """

    T: np.ndarray
    q: np.ndarray
    R: np.ndarray
    p: np.ndarray
    Jv: np.ndarray
    Jw: np.ndarray
    error: np.ndarray
    active: np.ndarray
    log: np.ndarray
    n_log: np.ndarray


class IPFOMoments(NamedTuple):
    """The moments of B fits' pairs and each fit's stop threshold.

    Attributes:
        sums: the moments (:class:`isf.fitting.moment_kernels.GroupMoments`).
        threshold: the least decrease of E that goes on, (B,) float64, m^2.
    """

    sums: GroupMoments
    threshold: np.ndarray


class IPFOParameters(NamedTuple):
    """The constants of IPFO for one gripper and :class:`isf.config.FitConfig`
    (:func:`isf.fitting._ipfo.ipfo_parameters`).

    Attributes:
        alpha: weight of the normal term, float, m.
        max_rotation: the largest palm rotation of an alternation, float, rad.
        tolerance: IPFO's stop tolerance per pair, float, m^2.
        max_iterations: alternations at most, int.
        move_fingers: whether the finger step runs, bool.
        q_lower, q_upper: joint limits, (n,) float64.
        step: the largest joint step, (n,) float64 (inf: none).
        damping: finger-step damping, float.
        max_rounds, kkt_tolerance: of :func:`isf.fitting._box_qp.solve_box_qps`, int and float.
        has_chain: whether ``chain`` holds the gripper's compiled kinematics, bool.
        chain: :class:`isf.gripper.chain.ChainArrays` (empty arrays when ``has_chain`` is off).
        frames: the contact links' Pinocchio frame ids, (L,) int64.
    """

    alpha: float
    max_rotation: float
    tolerance: float
    max_iterations: int
    move_fingers: bool
    q_lower: np.ndarray
    q_upper: np.ndarray
    step: np.ndarray
    damping: float
    max_rounds: int
    kkt_tolerance: float
    has_chain: bool
    chain: ChainArrays
    frames: np.ndarray


class IPFOAnswer(NamedTuple):
    """Python's answer to a request of :func:`alternate`, for the alternation it resumes at.

    Attributes:
        use_dq: whether ``dq`` answers a NEED_FINGER_STEP, bool.
        dq: the finger steps, (B, n) float64.
        use_links: whether the kinematics answer a NEED_KINEMATICS, bool.
        R, p, Jv, Jw: the contact-link kinematics at the new joints, as in :class:`IPFOState`.
    """

    use_dq: bool
    dq: np.ndarray
    use_links: bool
    R: np.ndarray
    p: np.ndarray
    Jv: np.ndarray
    Jw: np.ndarray


class IPFORequest(NamedTuple):
    """What :func:`alternate` returns: DONE, or what it needs to go on (n joints).

    Attributes:
        status: DONE, NEED_FINGER_STEP or NEED_KINEMATICS, int.
        alternation: the alternation that asks, int.
        AtA: for NEED_FINGER_STEP, the finger QPs' matrices, (B, n, n) float64.
        Atb, lower, upper: their vectors and step bounds, (B, n) float64.
        dq: the steps the active set found, (B, n) float64.
        exact: which of them it certified, (B,) bool.
        q_new: for NEED_KINEMATICS, the new joints, (B, n) float64.
        moved: the fits whose joints moved, (B,) bool.
    """

    status: int
    alternation: int
    AtA: np.ndarray
    Atb: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    dq: np.ndarray
    exact: np.ndarray
    q_new: np.ndarray
    moved: np.ndarray


@kernel
def no_answer(state):
    """The :class:`IPFOAnswer` of a first call: nothing answered."""
    return IPFOAnswer(False, np.zeros(state.q.shape), False, state.R, state.p, state.Jv, state.Jw)


@kernel
def _request(status, alternation, n_fits, n, q_new, moved):
    """An :class:`IPFORequest` without finger QPs."""
    empty3, empty2 = np.zeros((n_fits, n, n)), np.zeros((n_fits, n))
    return IPFORequest(status, alternation, empty3, empty2, empty2, empty2, empty2,
                       np.zeros(n_fits, dtype=np.bool_), q_new, moved)


@kernel
def alternate(state, moments, params, start, answer):
    """Alternations ``start .. max_iterations - 1`` of B fits, until every fit has stopped.

    Args:
        state: the fits' :class:`IPFOState`, updated in place.
        moments: their :class:`IPFOMoments`.
        params: :class:`IPFOParameters`.
        start: the alternation to begin with.
        answer: :class:`IPFOAnswer` to a request of alternation ``start`` (:func:`no_answer` for
            none).

    Returns:
        An :class:`IPFORequest`: DONE, or the request made in its ``alternation``.
    """
    T, q, R, p, Jv, Jw = state.T, state.q, state.R, state.p, state.Jv, state.Jw
    error, active, log, n_log = state.error, state.active, state.log, state.n_log
    m, threshold = moments.sums, moments.threshold
    q_lower, q_upper, step = params.q_lower, params.q_upper, params.step
    n_fits, n = q.shape
    alpha = params.alpha
    alpha2 = alpha * alpha
    none = np.zeros(n_fits, dtype=np.bool_)
    for it in range(start, params.max_iterations):
        resumed = it == start
        T_new = palm_updates(T, R, p, m.origin, m.fit_count, m.M, m.N, m.v, m.w, m.s, m.count,
                             alpha2, params.max_rotation)
        q_new = q.copy()
        R_new, p_new, Jv_new, Jw_new = R, p, Jv, Jw
        if params.move_fingers:
            AtA, Atb = finger_systems(T_new, R, p, Jv, Jw, m.origin, m.M, m.N, m.v, m.w, m.count,
                                      alpha)
            lower, upper = np.empty((n_fits, n)), np.empty((n_fits, n))
            for b in range(n_fits):
                for i in range(n):
                    lower[b, i] = min(max(q_lower[i] - q[b, i], -step[i]), 0.0)
                    upper[b, i] = max(min(q_upper[i] - q[b, i], step[i]), 0.0)
            if resumed and answer.use_dq:
                dq = answer.dq
            else:
                dq, exact = bounded_steps(AtA, Atb, lower, upper, params.damping,
                                          params.max_rounds, params.kkt_tolerance)
                if not exact.all():
                    return IPFORequest(NEED_FINGER_STEP, it, AtA, Atb, lower, upper, dq, exact,
                                       q_new, none)
            moved = np.zeros(n_fits, dtype=np.bool_)
            for b in range(n_fits):
                for i in range(n):
                    q_new[b, i] = min(max(q[b, i] + dq[b, i], q_lower[i]), q_upper[i])
                    moved[b] = moved[b] or (active[b] and q_new[b, i] != q[b, i])
            if moved.any():  # the same joints give the same kinematics
                if resumed and answer.use_links:
                    R_new, p_new, Jv_new, Jw_new = answer.R, answer.p, answer.Jv, answer.Jw
                elif params.has_chain:
                    rows = np.flatnonzero(moved)
                    fresh = compiled_frame_kinematics(q_new[rows], params.frames, params.chain)
                    R_fresh, p_fresh = fresh.rotations, fresh.positions
                    Jv_fresh, Jw_fresh = fresh.J_linear, fresh.J_angular
                    R_new, p_new, Jv_new, Jw_new = R.copy(), p.copy(), Jv.copy(), Jw.copy()
                    for k in range(len(rows)):
                        copy_into(R_new[rows[k]], R_fresh[k]), copy_into(p_new[rows[k]], p_fresh[k])
                        copy_into(Jv_new[rows[k]], Jv_fresh[k])
                        copy_into(Jw_new[rows[k]], Jw_fresh[k])
                else:
                    return _request(NEED_KINEMATICS, it, n_fits, n, q_new, moved)
        error_new = fit_errors(T_new, R_new, p_new, m.origin, m.M, m.N, m.v, m.beta2, m.w, m.count,
                               alpha2)
        going = False
        for b in range(n_fits):
            accept = active[b] and error_new[b] <= error[b]
            decrease = error[b] - error_new[b]
            if accept:
                copy_into(T[b], T_new[b]), copy_into(q[b], q_new[b])
                error[b] = error_new[b]
                copy_into(R[b], R_new[b]), copy_into(p[b], p_new[b])
                copy_into(Jv[b], Jv_new[b]), copy_into(Jw[b], Jw_new[b])
                log[b, n_log[b]] = error[b]
                n_log[b] += 1
            active[b] = accept and decrease > threshold[b]
            going = going or active[b]
        if not going:
            break
    return _request(DONE, params.max_iterations, n_fits, n, q, none)
