"""Iterative palm-finger optimisation (paper Algorithm 1), for fixed correspondences."""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from .config import FitConfig
from .exceptions import QPStepError
from .finger_step import FingerStepQP
from .gripper import Gripper, LinkKinematics
from .palm_step import palm_step
from .se3 import cross

__all__ = ["IPFOResult", "MatchedPairs", "ipfo"]

logger = logging.getLogger(__name__)


class IPFOResult(NamedTuple):
    """Outcome of one IPFO run.

    Attributes:
        T_object_gripper: palm pose, (4, 4).
        q: joint vector, (n_joints,).
        error: total fitting error E at the result, m^2 (eq. 9a).
        mean_distance: mean |point-to-plane distance| of the pairs at the result, metres.
        iterations: palm/finger alternations kept.
        errors: E after each kept alternation (the paper's Fig. 5b), m^2.
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    error: float
    mean_distance: float
    iterations: int
    errors: tuple[float, ...]


class MatchedPairs:
    """Matched (contact point, object point) pairs, grouped by the contact point's link.

    Grouping lets every per-link quantity (pose, Jacobian) act on a block of
    points with one matrix product instead of per-point tensors.

    Args:
        gripper: the gripper.
        point_index: indices of the matched contact points into the gripper's points, (K,).
        targets: matched object points, object frame, (K, 3), metres.
        target_normals: object normals at the targets, (K, 3).
    """

    def __init__(self, gripper: Gripper, point_index, targets, target_normals):
        order = np.argsort(gripper.point_link[point_index], kind="stable")
        self.gripper = gripper
        self.point_index = np.asarray(point_index)[order]
        self.targets = np.asarray(targets)[order]
        self.target_normals = np.asarray(target_normals)[order]
        self._points = gripper.points_link[self.point_index]
        self._normals = gripper.normals_link[self.point_index]
        links = gripper.point_link[self.point_index]
        edges = np.flatnonzero(np.diff(links)) + 1
        starts = np.r_[0, edges]
        stops = np.r_[edges, len(links)]
        self._groups = [(int(links[a]), slice(int(a), int(b))) for a, b in zip(starts, stops) if b > a]

    def __len__(self) -> int:
        return len(self.point_index)

    def evaluate(self, links: LinkKinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact points, normals and offsets from their link origins, gripper frame, each (K, 3)."""
        offsets = np.empty_like(self._points)
        normals = np.empty_like(self._normals)
        points = np.empty_like(self._points)
        for k, s in self._groups:
            R = links.rotations[k]
            offsets[s] = self._points[s] @ R.T
            normals[s] = self._normals[s] @ R.T
            points[s] = offsets[s] + links.positions[k]
        return points, normals, offsets

    def residuals(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point-to-plane distances (K,) in metres and normal terms ``(R n^p)^T n^q + 1`` (K,) at palm pose ``T``."""
        R, t = T[:3, :3], T[:3, 3]
        d = np.einsum("kj,kj->k", points @ R.T + t - self.targets, self.target_normals)
        c = np.einsum("kj,kj->k", normals @ R.T, self.target_normals) + 1.0
        return d, c

    def error(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray, normal_weight: float) -> float:
        """``E = E_p + alpha^2 E_n`` (eq. 7-9) at palm pose ``T`` for gripper-frame points/normals, m^2."""
        d, c = self.residuals(T, points, normals)
        return float(d @ d + normal_weight**2 * (c @ c))

    def finger_rows(self, T, points, normals, offsets, links: LinkKinematics, normal_weight: float):
        """Rows ``A`` (K', n) and right-hand side ``b`` (K',) of the finger least squares.

        With the palm at ``T`` fixed, moving the joints by ``dq`` moves point ``i``
        (on link ``k``, offset ``r_i`` from its origin) by ``R (Jv_k + Jw_k x r_i) dq``,
        so its point-to-plane row is ``m_i^T Jv_k + (r_i x m_i)^T Jw_k`` with
        ``m_i = R^T n^q_i``, and its right-hand side ``-(R p_i + t - q_i)^T n^q_i``.
        Joints that turn links add alpha-weighted normal rows
        ``alpha (n_i x m_i)^T Jw_k``, ``-alpha (n_i^T m_i + 1)``.
        """
        R, t = T[:3, :3], T[:3, 3]
        m = self.target_normals @ R
        n_joints = links.J_linear.shape[2]
        A = np.empty((len(self), n_joints))
        for k, s in self._groups:
            A[s] = m[s] @ links.J_linear[k] + cross(offsets[s], m[s]) @ links.J_angular[k]
        b = -np.einsum("kj,kj->k", points @ R.T + t - self.targets, self.target_normals)
        if normal_weight > 0.0 and np.any(links.J_angular):
            An = np.empty((len(self), n_joints))
            for k, s in self._groups:
                An[s] = normal_weight * (cross(normals[s], m[s]) @ links.J_angular[k])
            bn = -normal_weight * (np.einsum("kj,kj->k", normals, m) + 1.0)
            A, b = np.concatenate([A, An]), np.concatenate([b, bn])
        return A, b


def ipfo(pairs: MatchedPairs, T: np.ndarray, q: np.ndarray, qp: FingerStepQP | None,
         config: FitConfig) -> IPFOResult:
    """Alternate palm and finger steps until E stops decreasing (Algorithm 1).

    A finger step OSQP cannot solve is skipped (logged as a warning): the
    alternation then moves the palm only. The loop stops when E per pair decreases by less than
    ``config.ipfo_tolerance``, after ``config.max_ipfo_iterations`` alternations,
    or when an alternation would raise E (that alternation is undone).

    Args:
        pairs: the matched pairs (fixed during IPFO).
        T: initial ``T_object_gripper``, (4, 4).
        q: initial joints, (n_joints,).
        qp: the finger-step QP (reused across calls), or None for a gripper without joints.
        config: fit parameters.
    """
    gripper = pairs.gripper
    alpha = config.normal_weight
    threshold = config.ipfo_tolerance * len(pairs)
    move_fingers = qp is not None and not config.lock_fingers
    links = gripper.link_kinematics(q)
    points, normals, offsets = pairs.evaluate(links)
    error = pairs.error(T, points, normals, alpha)
    errors = []
    while len(errors) < config.max_ipfo_iterations:
        R, t = T[:3, :3], T[:3, 3]
        T_new = palm_step(
            points @ R.T + t, normals @ R.T, pairs.targets, pairs.target_normals,
            normal_weight=alpha, max_rotation=config.max_rotation_step,
        ) @ T
        q_new = q
        if move_fingers:
            A, b = pairs.finger_rows(T_new, points, normals, offsets, links, alpha)
            step = np.where(gripper.revolute, config.max_revolute_step, np.inf)
            lower = np.minimum(np.maximum(gripper.lower - q, -step), 0.0)
            upper = np.maximum(np.minimum(gripper.upper - q, step), 0.0)
            try:
                q_new = gripper.clip(q + qp.solve(A, b, lower, upper))
            except QPStepError as err:  # numerically hard step: keep the fingers, go on with the palm
                logger.warning("finger step skipped: %s", err)
                q_new = q
            links_new = gripper.link_kinematics(q_new)
            points_new, normals_new, offsets_new = pairs.evaluate(links_new)
        else:
            links_new, points_new, normals_new, offsets_new = links, points, normals, offsets
        error_new = pairs.error(T_new, points_new, normals_new, alpha)
        if error_new > error:
            break
        decrease = error - error_new
        T, q, error = T_new, q_new, error_new
        links, points, normals, offsets = links_new, points_new, normals_new, offsets_new
        errors.append(error)
        if decrease <= threshold:
            break
    mean_distance = float(np.mean(np.abs(pairs.residuals(T, points, normals)[0])))
    return IPFOResult(T, q, error, mean_distance, len(errors), tuple(errors))
