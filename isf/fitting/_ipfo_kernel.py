"""Algorithm 1 (IPFO) of B fits as one compiled loop, paused for what only Python can do.

:func:`alternate` runs the alternations of every fit (palm step, finger step, kinematics,
the error test that keeps or undoes the alternation, the stop rule) with the kernels of
:mod:`isf.fitting.moment_kernels`, :mod:`isf.fitting._box_qp` and :mod:`isf.gripper.chain`. Two things it cannot do
itself; for them it returns a request and is resumed at the same alternation with the
answer (:func:`isf.fitting._ipfo.answer_requests` drives it):

* ``NEED_FINGER_STEP``: a multi-joint finger QP the active set could not certify (it
  goes to OSQP);
* ``NEED_KINEMATICS``: a gripper whose joints :mod:`isf.gripper.chain` does not cover (Pinocchio).

An alternation is recomputed from its start when resumed (the same numbers: every step is
deterministic); the given answer replaces only the part that was asked for.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..gripper.chain import compiled_frame_kinematics
from ._finger_step import bounded_steps
from .moment_kernels import finger_systems, fit_errors, palm_updates

__all__ = ["DONE", "NEED_FINGER_STEP", "NEED_KINEMATICS", "alternate", "resume"]

DONE, NEED_FINGER_STEP, NEED_KINEMATICS = 0, 1, 2


@njit(cache=True, nogil=True, error_model="numpy")
def alternate(T, q, R, p, Jv, Jw, error, active, log, n_log,
              origin, fit_count, M, N, v, beta2, w, s, count,
              alpha, max_rotation, threshold, max_iterations, move_fingers,
              q_lower, q_upper, step, damping, max_rounds, kkt_tolerance,
              has_chain, nv, ints, reals, placements, frame_joints, frame_placements, frames,
              start, use_dq, dq_given, use_links, R_given, p_given, Jv_given, Jw_given):
    """Alternations ``start .. max_iterations - 1`` of B fits, until every fit has stopped.

    State, updated in place: palm poses ``T`` (B, 4, 4), joints ``q`` (B, n), contact-link
    kinematics ``R, p, Jv, Jw`` (B, L, ...), errors ``error`` (B,) (m^2), ``active`` (B,),
    and the error after each kept alternation ``log[b, :n_log[b]]``.

    Args:
        origin, fit_count, M, N, v, beta2, w, s, count: the moments
            (:func:`isf.fitting.moment_kernels.group_moments`).
        alpha, max_rotation, threshold, max_iterations, move_fingers: as in
            :func:`isf.fitting._ipfo.ipfo` (``threshold`` (B,): the least decrease of E that goes on).
        q_lower, q_upper, step: joint limits and the largest joint step, (n,).
        damping, max_rounds, kkt_tolerance: of the finger QP and of
            :func:`isf.fitting._box_qp.solve_box_qps`.
        has_chain, nv, ints, reals, placements, frame_joints, frame_placements, frames: the
            compiled chain (:class:`isf.gripper.chain.KinematicChain`) and the contact links' frame ids.
        start: the alternation to begin with.
        use_dq, dq_given: the answer (B, n) to a NEED_FINGER_STEP of alternation ``start``.
        use_links, R_given, p_given, Jv_given, Jw_given: the answer to a NEED_KINEMATICS.

    Returns:
        ``(status, alternation, AtA, Atb, lower, upper, dq, exact, q_new, moved)``: ``status``
        is DONE or the request made in ``alternation``; for NEED_FINGER_STEP the finger
        QPs (``AtA`` (B, n, n), ``Atb``, ``lower``, ``upper`` (B, n)), ``dq`` and which are
        ``exact``; for NEED_KINEMATICS the new joints ``q_new`` and the fits that ``moved``.
    """
    n_fits, n = q.shape
    alpha2 = alpha * alpha
    empty3, empty2 = np.zeros((n_fits, n, n)), np.zeros((n_fits, n))
    none = np.zeros(n_fits, dtype=np.bool_)
    for it in range(start, max_iterations):
        resumed = it == start
        T_new = palm_updates(T, R, p, origin, fit_count, M, N, v, w, s, count, alpha2, max_rotation)
        q_new = q.copy()
        R_new, p_new, Jv_new, Jw_new = R, p, Jv, Jw
        if move_fingers:
            AtA, Atb = finger_systems(T_new, R, p, Jv, Jw, origin, M, N, v, w, count, alpha)
            lower, upper = np.empty((n_fits, n)), np.empty((n_fits, n))
            for b in range(n_fits):
                for i in range(n):
                    lower[b, i] = min(max(q_lower[i] - q[b, i], -step[i]), 0.0)
                    upper[b, i] = max(min(q_upper[i] - q[b, i], step[i]), 0.0)
            if resumed and use_dq:
                dq = dq_given
            else:
                dq, exact = bounded_steps(AtA, Atb, lower, upper, damping, max_rounds, kkt_tolerance)
                if not exact.all():
                    return NEED_FINGER_STEP, it, AtA, Atb, lower, upper, dq, exact, q_new, none
            moved = np.zeros(n_fits, dtype=np.bool_)
            for b in range(n_fits):
                for i in range(n):
                    q_new[b, i] = min(max(q[b, i] + dq[b, i], q_lower[i]), q_upper[i])
                    moved[b] = moved[b] or (active[b] and q_new[b, i] != q[b, i])
            if moved.any():  # the same joints give the same kinematics
                if resumed and use_links:
                    R_new, p_new, Jv_new, Jw_new = R_given, p_given, Jv_given, Jw_given
                elif has_chain:
                    rows = np.flatnonzero(moved)
                    fresh = compiled_frame_kinematics(q_new[rows], frames, nv, ints, reals, placements,
                                              frame_joints, frame_placements)
                    R_new, p_new, Jv_new, Jw_new = R.copy(), p.copy(), Jv.copy(), Jw.copy()
                    for k in range(len(rows)):
                        R_new[rows[k]], p_new[rows[k]] = fresh[0][k], fresh[1][k]
                        Jv_new[rows[k]], Jw_new[rows[k]] = fresh[2][k], fresh[3][k]
                else:
                    return NEED_KINEMATICS, it, empty3, empty2, empty2, empty2, empty2, none, q_new, moved
        error_new = fit_errors(T_new, R_new, p_new, origin, M, N, v, beta2, w, count, alpha2)
        going = False
        for b in range(n_fits):
            accept = active[b] and error_new[b] <= error[b]
            decrease = error[b] - error_new[b]
            if accept:
                T[b], q[b], error[b] = T_new[b], q_new[b], error_new[b]
                R[b], p[b], Jv[b], Jw[b] = R_new[b], p_new[b], Jv_new[b], Jw_new[b]
                log[b, n_log[b]] = error[b]
                n_log[b] += 1
            active[b] = accept and decrease > threshold[b]
            going = going or active[b]
        if not going:
            break
    return DONE, max_iterations, empty3, empty2, empty2, empty2, empty2, none, q, none


@njit(cache=True, nogil=True, error_model="numpy")
def resume(state, moments, params, start, use_dq, dq_given, use_links, R_given, p_given, Jv_given, Jw_given):
    """:func:`alternate` on its arguments grouped: ``state`` = ``(T, q, R, p, Jv, Jw, error,
    active, log, n_log)``, ``moments`` = the moments and ``threshold``, ``params`` =
    :func:`isf.fitting._ipfo.ipfo_parameters`; the rest as :func:`alternate` takes them."""
    T, q, R, p, Jv, Jw, error, active, log, n_log = state
    origin, fit_count, M, N, v, beta2, w, s, count, threshold = moments
    (alpha, max_rotation, _, max_iterations, move_fingers, q_lower, q_upper, step, damping, max_rounds,
     kkt_tolerance, has_chain, nv, ints, reals, placements, frame_joints, frame_placements, frames) = params
    return alternate(T, q, R, p, Jv, Jw, error, active, log, n_log,
                     origin, fit_count, M, N, v, beta2, w, s, count,
                     alpha, max_rotation, threshold, max_iterations, move_fingers,
                     q_lower, q_upper, step, damping, max_rounds, kkt_tolerance,
                     has_chain, nv, ints, reals, placements, frame_joints, frame_placements, frames,
                     start, use_dq, dq_given, use_links, R_given, p_given, Jv_given, Jw_given)
