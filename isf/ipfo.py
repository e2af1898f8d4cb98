"""Iterative palm-finger optimisation (paper Algorithm 1) for fixed correspondences, many fits at once.

Every fit of a batch runs its own Algorithm 1 (its own stop decisions); the arithmetic of
all fits is done together: one batched 6x6 palm solve and one batched joint solve per
alternation. The pairs of all fits are stored back to back (:class:`PairBatch`, which
also evaluates them pair by pair); the alternations work on their moments
(:class:`isf.moments.PairMoments`), so an alternation costs the same for 50 pairs or 5000.
The alternations themselves run compiled (:func:`isf.ipfo_kernel.alternate`); this module
answers what they cannot do themselves (OSQP finger steps, Pinocchio kinematics).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import box_qp
from .config import FitConfig
from .finger_step import FingerStepQP, solve_uncertified
from .gripper import Gripper, LinkKinematics
from .ipfo_kernel import DONE, NEED_FINGER_STEP, resume
from .moment_kernels import points_in_object
from .moments import PairMoments
from .se3 import cross
from .segments import Segments

__all__ = ["IPFOResult", "PairBatch", "answer_requests", "ipfo", "ipfo_parameters"]

_NO_CHAIN = (0, np.zeros((0, 6), dtype=np.int64), np.zeros((0, 5)), np.zeros((0, 3, 4)),
             np.zeros(0, dtype=np.int64), np.zeros((0, 3, 4)))
"""Stand-ins for the compiled chain's arrays, for a gripper without one."""


def _rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise ``R_k v_k`` for R (K, 3, 3) and v (K, 3), (K, 3)."""
    return np.einsum("kij,kj->ki", R, v)


class PairBatch:
    """Matched (contact point, object point) pairs of B fits, stored fit after fit.

    Args:
        gripper: the gripper.
        segments: the fit of each pair (pairs grouped by fit).
        point_index: indices of the matched contact points into the gripper's points, (K,).
        targets: matched object points, object frame, (K, 3), metres.
        target_normals: object normals at the targets, (K, 3).
    """

    def __init__(self, gripper: Gripper, segments: Segments, point_index, targets, target_normals):
        self.gripper = gripper
        self.segments = segments
        self.point_index = np.asarray(point_index)
        self.targets = np.asarray(targets, dtype=float)
        self.target_normals = np.asarray(target_normals, dtype=float)
        self.link = gripper.point_link[self.point_index]
        """Contact link of each pair (index into ``gripper.contact_links``), (K,)."""
        self.points_link = gripper.points_link[self.point_index]
        """Contact points in their link frames, (K, 3), metres."""
        self.normals_link = gripper.normals_link[self.point_index]
        """Contact normals in their link frames, (K, 3)."""

    def __len__(self) -> int:
        return len(self.point_index)

    def evaluate(self, links: LinkKinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact points, normals and offsets from their link origins, gripper frame, each (K, 3).

        Args:
            links: kinematics of the B fits (arrays with a leading fit axis, see
                :meth:`Gripper.link_kinematics_many`).
        """
        fit, link = self.segments.ids, self.link
        R = links.rotations[fit, link]
        offsets = _rotate(R, self.points_link)
        return offsets + links.positions[fit, link], _rotate(R, self.normals_link), offsets

    def to_object(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gripper-frame points and normals (K, 3) moved by each pair's palm pose ``T`` (B, 4, 4)."""
        Tk = T[self.segments.ids]
        R = Tk[:, :3, :3]
        return _rotate(R, points) + Tk[:, :3, 3], _rotate(R, normals)

    def residuals(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point-to-plane distances (K,) in metres and normal terms ``(R n^p)^T n^q + 1`` (K,).

        Args:
            T: palm poses ``T_object_gripper`` of the B fits, (B, 4, 4).
            points, normals: gripper-frame contact points and normals, (K, 3).
        """
        p, n = self.to_object(T, points, normals)
        d = np.einsum("kj,kj->k", p - self.targets, self.target_normals)
        c = np.einsum("kj,kj->k", n, self.target_normals) + 1.0
        return d, c

    def errors(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray, normal_weight: float) -> np.ndarray:
        """``E = E_p + alpha^2 E_n`` (eq. 7-9) of each fit, (B,), m^2."""
        d, c = self.residuals(T, points, normals)
        return self.segments.sum(d * d + normal_weight**2 * (c * c))

    def finger_rows(self, T, points, normals, offsets, links: LinkKinematics, normal_weight: float):
        """Rows of the finger least squares: ``A`` (K, n), ``b`` (K,), and the normal rows
        ``An`` (K, n), ``bn`` (K,) (None when alpha is 0 or no joint turns a link).

        With the palm at ``T`` fixed, moving the joints by ``dq`` moves point ``i``
        (on link ``k``, offset ``r_i`` from its origin) by ``R (Jv_k + Jw_k x r_i) dq``,
        so its point-to-plane row is ``m_i^T Jv_k + (r_i x m_i)^T Jw_k`` with
        ``m_i = R^T n^q_i``, and its right-hand side ``-(R p_i + t - q_i)^T n^q_i``.
        Joints that turn links add alpha-weighted normal rows
        ``alpha (n_i x m_i)^T Jw_k``, ``-alpha (n_i^T m_i + 1)``.
        """
        fit, link = self.segments.ids, self.link
        R = T[fit, :3, :3]
        m = np.einsum("kji,kj->ki", R, self.target_normals)
        Jv, Jw = links.J_linear[fit, link], links.J_angular[fit, link]
        A = np.einsum("kj,kjn->kn", m, Jv) + np.einsum("kj,kjn->kn", cross(offsets, m), Jw)
        b = -self.residuals(T, points, normals)[0]
        if normal_weight > 0.0 and np.any(links.J_angular):
            An = normal_weight * np.einsum("kj,kjn->kn", cross(normals, m), Jw)
            bn = -normal_weight * (np.einsum("kj,kj->k", normals, m) + 1.0)
            return A, b, An, bn
        return A, b, None, None

    def finger_system(self, T, points, normals, offsets, links, normal_weight):
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b`` (B, n)."""
        A, b, An, bn = self.finger_rows(T, points, normals, offsets, links, normal_weight)
        AtA = self.segments.sum(A[:, :, None] * A[:, None, :])
        Atb = self.segments.sum(A * b[:, None])
        if An is not None:
            AtA += self.segments.sum(An[:, :, None] * An[:, None, :])
            Atb += self.segments.sum(An * bn[:, None])
        return AtA, Atb


class IPFOResult(NamedTuple):
    """Outcome of IPFO for B fits.

    Attributes:
        T_object_gripper: palm poses, (B, 4, 4).
        q: joint vectors, (B, n_joints).
        error: total fitting error E at the result, (B,), m^2 (eq. 9a).
        mean_distance: mean absolute point-to-plane distance of each fit's pairs at the result, (B,), metres.
        errors: per fit, E after each kept alternation (the paper's Fig. 5b), m^2.
        links: contact-link kinematics at the resulting joints (leading fit axis).
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    error: np.ndarray
    mean_distance: np.ndarray
    errors: list[tuple[float, ...]]
    links: LinkKinematics


def _kinematics_where(gripper: Gripper, links: LinkKinematics, q: np.ndarray, mask: np.ndarray) -> LinkKinematics:
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


def ipfo_parameters(gripper: Gripper, config: FitConfig, move_fingers: bool = True) -> tuple:
    """The constants of :func:`isf.ipfo_kernel.alternate` for ``gripper`` and ``config``:
    ``(alpha, max_rotation, ipfo_tolerance, max_ipfo_iterations, move_fingers, q_lower,
    q_upper, largest joint step, finger damping, active-set rounds, KKT tolerance, has_chain,
    the chain's nv and arrays, the contact links' frame ids)``. The fingers move only when
    ``move_fingers``, the gripper has joints and ``config.lock_fingers`` is off."""
    chain = gripper.chain
    chain_arrays = (chain.nv, chain.joint_ints, chain.joint_reals, chain.joint_placements,
                    chain.frame_joints, chain.frame_placements) if chain is not None else _NO_CHAIN
    return (float(config.normal_weight), float(config.max_rotation_step), float(config.ipfo_tolerance),
            int(config.max_ipfo_iterations), bool(move_fingers and gripper.n_joints and not config.lock_fingers),
            gripper.lower, gripper.upper, np.where(gripper.revolute, config.max_revolute_step, np.inf),
            float(config.finger_damping), box_qp.MAX_ROUNDS, box_qp.KKT_TOLERANCE, chain is not None,
            *chain_arrays, gripper.link_frames)


def answer_requests(gripper: Gripper, qps: list[FingerStepQP] | None, state: tuple, moments: tuple,
                    params: tuple, reply: tuple) -> None:
    """Drive :func:`isf.ipfo_kernel.alternate` to the end from its ``reply`` to a first call
    (from alternation 0), answering each request: OSQP for the finger steps the active set
    could not certify, Pinocchio for joints the compiled chain does not cover. ``state``,
    ``moments``, ``params``: as :func:`isf.ipfo_kernel.resume` takes them; ``state`` is
    updated in place. ``qps``: one finger-step QP per fit."""
    links = LinkKinematics(*state[2:6])
    start, use_dq, dq_given, use_links, links_given = 0, False, np.zeros(state[1].shape), False, links
    while reply[0] != DONE:
        status, at, AtA, Atb, lower, upper, dq, exact, q_new, moved = reply
        if at != start:  # answers belong to one alternation
            use_dq, use_links = False, False
        if status == NEED_FINGER_STEP:  # OSQP for the steps the active set could not certify
            solve_uncertified(dq, exact, AtA, Atb, lower, upper, qps)
            use_dq, dq_given = True, dq
        else:  # NEED_KINEMATICS: joints the compiled chain does not cover
            use_links, links_given = True, _kinematics_where(gripper, links, q_new, moved)
        start = at
        reply = resume(state, moments, params, start, use_dq, dq_given, use_links, *links_given)


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
    state = (T, q, *links, error, np.ones(n_fits, dtype=bool), log, n_log)
    sums = (moments.origin, moments.fit_count, moments.M, moments.N, moments.v, moments.beta2, moments.w,
            moments.s, moments.count, config.ipfo_tolerance * seg.counts.astype(float))
    params = ipfo_parameters(gripper, config, qps is not None)
    reply = resume(state, sums, params, 0, False, np.zeros(q.shape), False, *links)
    answer_requests(gripper, qps, state, sums, params, reply)
    points, _ = points_in_object(T, links.rotations, links.positions, seg.ids, pairs.link,
                                 pairs.points_link, pairs.normals_link)
    mean_distance = seg.mean(np.abs(np.einsum("kj,kj->k", points - pairs.targets, pairs.target_normals)))
    errors = [tuple(log[b, :k].tolist()) for b, k in enumerate(n_log.tolist())]
    return IPFOResult(T, q, error, mean_distance, errors, links)
