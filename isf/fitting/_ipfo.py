"""Iterative palm-finger optimisation (paper Algorithm 1) for fixed correspondences, many fits.

Every fit of a batch runs its own Algorithm 1 (its own stop decisions); the arithmetic of
all fits is done together: one batched 6x6 palm solve and one batched joint solve per
alternation. The pairs of all fits are stored back to back
(:class:`isf.fitting.reference.PairBatch`, which also evaluates them pair by pair); the
alternations work on their moments (:class:`isf.fitting._moments.PairMoments`), so an
alternation costs the same for 50 pairs or 5000.
The alternations themselves run compiled (:func:`isf.fitting._ipfo_kernel.alternate`); this module
answers what they cannot do themselves (OSQP finger steps, Pinocchio kinematics).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..config import FitConfig
from ..gripper.chain import ChainArrays
from ..gripper.model import Gripper, LinkKinematics
from . import _box_qp as box_qp
from ._finger_step import FingerStepQP, solve_uncertified
from ._ipfo_kernel import (
    DONE,
    NEED_FINGER_STEP,
    IPFOMoments,
    IPFOParameters,
    IPFORequest,
    IPFOState,
    alternate,
    no_answer,
)
from ._moments import PairMoments
from .moment_kernels import GroupMoments, points_in_object

if TYPE_CHECKING:
    from .reference import PairBatch

__all__ = ["IPFOResult", "answer_requests", "ipfo", "ipfo_parameters"]

_NO_CHAIN = ChainArrays(0, np.zeros((0, 6), dtype=np.int64), np.zeros((0, 5)), np.zeros((0, 3, 4)),
                        np.zeros(0, dtype=np.int64), np.zeros((0, 3, 4)))
"""Stand-ins for the compiled chain's arrays, for a gripper without one."""


class IPFOResult(NamedTuple):
    """Outcome of IPFO for B fits.

    Attributes:
        T_object_gripper: palm poses, (B, 4, 4).
        q: joint vectors, (B, n_joints).
        error: total fitting error E at the result, (B,), m^2 (eq. 9a).
        mean_distance: mean absolute point-to-plane distance of each fit's pairs at the result,
            (B,), metres.
        errors: per fit, E after each kept alternation (the paper's Fig. 5b), m^2.
        links: contact-link kinematics at the resulting joints (leading fit axis).
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    error: np.ndarray
    mean_distance: np.ndarray
    errors: list[tuple[float, ...]]
    links: LinkKinematics


def _kinematics_where(gripper: Gripper, links: LinkKinematics, q: np.ndarray,
                      mask: np.ndarray) -> LinkKinematics:
    """Kinematics at ``q`` (B, n) for the fits in ``mask`` (B,); the others keep ``links``."""
    if mask.all():
        return gripper.link_kinematics_many(q)
    if not mask.any():
        return links
    fresh = gripper.link_kinematics_many(q[mask])
    arrays = [a.copy() for a in links]
    for a, f in zip(arrays, fresh):
        a[mask] = f
    return LinkKinematics(*arrays)


def ipfo_parameters(gripper: Gripper, config: FitConfig,
                    move_fingers: bool = True) -> IPFOParameters:
    """The constants of :func:`isf.fitting._ipfo_kernel.alternate` for ``gripper`` and ``config``.
    The fingers move only when ``move_fingers``, the gripper has joints and
    ``config.lock_fingers`` is off."""
    chain = gripper.chain
    return IPFOParameters(
        alpha=float(config.normal_weight), max_rotation=float(config.max_rotation_step),
        tolerance=float(config.ipfo_tolerance), max_iterations=int(config.max_ipfo_iterations),
        move_fingers=bool(move_fingers and gripper.n_joints and not config.lock_fingers),
        q_lower=gripper.lower, q_upper=gripper.upper,
        step=np.where(gripper.revolute, config.max_revolute_step, np.inf),
        damping=float(config.finger_damping), max_rounds=box_qp.MAX_ROUNDS,
        kkt_tolerance=box_qp.KKT_TOLERANCE, has_chain=chain is not None,
        chain=_NO_CHAIN if chain is None else chain.arrays, frames=gripper.link_frames)


def answer_requests(gripper: Gripper, qps: list[FingerStepQP] | None, state: IPFOState,
                    moments: IPFOMoments, params: IPFOParameters, request: IPFORequest) -> None:
    """Drive :func:`isf.fitting._ipfo_kernel.alternate` to the end from its ``request`` on a first
    call (from alternation 0), answering each request: OSQP for the finger steps the active set
    could not certify, Pinocchio for joints the compiled chain does not cover. ``state`` is
    updated in place. ``qps``: one finger-step QP per fit."""
    links = LinkKinematics(state.R, state.p, state.Jv, state.Jw)
    answer, answer_at = no_answer(state), 0
    while request.status != DONE:
        if request.alternation != answer_at:  # answers belong to one alternation
            answer = answer._replace(use_dq=False, use_links=False)
        if request.status == NEED_FINGER_STEP:  # OSQP for the steps the active set left
            r = request
            solve_uncertified(r.dq, r.exact, r.AtA, r.Atb, r.lower, r.upper, qps)
            answer = answer._replace(use_dq=True, dq=r.dq)
        else:  # NEED_KINEMATICS: joints the compiled chain does not cover
            fresh = _kinematics_where(gripper, links, request.q_new, request.moved)
            answer = answer._replace(use_links=True, R=fresh.rotations, p=fresh.positions,
                                     Jv=fresh.J_linear, Jw=fresh.J_angular)
        answer_at = request.alternation
        request = alternate(state, moments, params, answer_at, answer)


def ipfo(pairs: PairBatch, T: np.ndarray, q: np.ndarray, qps: list[FingerStepQP] | None,
         config: FitConfig, links: LinkKinematics | None = None) -> IPFOResult:
    """Alternate palm and finger steps until E stops decreasing (Algorithm 1), for each fit.

    A fit stops when its E per pair decreases by less than ``config.ipfo_tolerance``,
    after ``config.max_ipfo_iterations`` alternations, or when an alternation would
    raise its E (that alternation is undone). A finger step OSQP cannot solve is
    skipped (logged as a warning): that alternation moves the palm only.

    Args:
        pairs: the matched pairs of B fits (fixed during IPFO).
        T: initial ``T_object_gripper`` of each fit, (B, 4, 4).
        q: initial joints, (B, n_joints).
        qps: one finger-step QP per fit (reused across calls), or None for a gripper without joints.
        config: fit parameters.
        links: the contact-link kinematics at ``q`` when the caller has them (arrays (B, L, ...)).
    """
    gripper, seg = pairs.gripper, pairs.segments
    n_fits = len(seg)
    moments = PairMoments(seg.ids, pairs.link, pairs.points_link, pairs.normals_link, pairs.targets,
                          pairs.target_normals, n_fits, len(gripper.contact_links))
    if links is None:
        links = gripper.link_kinematics_many(q)
    T, q = np.array(T, dtype=float), np.array(q, dtype=float).reshape(n_fits, gripper.n_joints)
    links = LinkKinematics(*(np.array(a, dtype=float) for a in links))  # updated in place
    error = moments.errors(T, links, config.normal_weight)
    log = np.empty((n_fits, config.max_ipfo_iterations))
    n_log = np.zeros(n_fits, dtype=np.int64)
    state = IPFOState(T, q, links.rotations, links.positions, links.J_linear, links.J_angular,
                      error, np.ones(n_fits, dtype=bool), log, n_log)
    sums = IPFOMoments(GroupMoments(moments.origin, moments.fit_count, moments.M, moments.N,
                                    moments.v, moments.beta2, moments.w, moments.s, moments.count),
                       config.ipfo_tolerance * seg.counts.astype(float))
    params = ipfo_parameters(gripper, config, qps is not None)
    request = alternate(state, sums, params, 0, no_answer(state))
    answer_requests(gripper, qps, state, sums, params, request)
    points, _ = points_in_object(T, links.rotations, links.positions, seg.ids, pairs.link,
                                 pairs.points_link, pairs.normals_link)
    mean_distance = seg.mean(np.abs(np.einsum("kj,kj->k", points - pairs.targets,
                                              pairs.target_normals)))
    errors = [tuple(log[b, :k].tolist()) for b, k in enumerate(n_log.tolist())]
    return IPFOResult(T, q, error, mean_distance, errors, links)
