"""Iterative palm-finger optimisation (paper Algorithm 1), for fixed correspondences."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .config import FitConfig
from .finger_step import FingerStepQP, finger_rows
from .gripper import Gripper
from .palm_step import palm_step

__all__ = ["IPFOResult", "fitting_error", "ipfo"]


class IPFOResult(NamedTuple):
    """Outcome of one IPFO run.

    Attributes:
        T_object_gripper: palm pose, (4, 4).
        q: joint vector, (n_joints,).
        error: total fitting error E at the result, m^2 (eq. 9a).
        iterations: palm/finger alternations performed.
        errors: E after each alternation (the paper's Fig. 5b), m^2.
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    error: float
    iterations: int
    errors: tuple[float, ...]


def fitting_error(
    T: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    targets: np.ndarray,
    target_normals: np.ndarray,
    normal_weight: float,
) -> float:
    """``E = E_p + alpha^2 E_n`` (eq. 7-9) for contact points given in the gripper frame, m^2.

    Args:
        T: ``T_object_gripper``, (4, 4).
        points, normals: matched contact points and normals, gripper frame, (K, 3).
        targets, target_normals: their object points and normals, (K, 3).
        normal_weight: ``alpha``, metres.
    """
    R, t = T[:3, :3], T[:3, 3]
    d = np.einsum("kj,kj->k", points @ R.T + t - targets, target_normals)
    c = np.einsum("kj,kj->k", normals @ R.T, target_normals) + 1.0
    return float(d @ d + normal_weight**2 * (c @ c))


def ipfo(
    gripper: Gripper,
    point_index: np.ndarray,
    targets: np.ndarray,
    target_normals: np.ndarray,
    T: np.ndarray,
    q: np.ndarray,
    qp: FingerStepQP,
    config: FitConfig,
) -> IPFOResult:
    """Alternate palm and finger steps until E stops decreasing (Algorithm 1).

    The loop stops when E per pair decreases by less than
    ``config.ipfo_tolerance``, after ``config.max_ipfo_iterations`` alternations,
    or when an alternation would raise E (that alternation is undone).

    Args:
        gripper: the gripper.
        point_index: indices of the matched contact points into the gripper's points, (K,).
        targets, target_normals: matched object points and normals, object frame, (K, 3).
        T: initial ``T_object_gripper``, (4, 4).
        q: initial joints, (n_joints,).
        qp: the finger-step QP (reused across calls).
        config: fit parameters.
    """
    alpha = config.normal_weight
    threshold = config.ipfo_tolerance * len(point_index)
    kin = gripper.contact_kinematics(q, point_index)
    error = fitting_error(T, kin.points, kin.normals, targets, target_normals, alpha)
    errors = []
    iterations = 0
    while iterations < config.max_ipfo_iterations:
        iterations += 1
        R, t = T[:3, :3], T[:3, 3]
        T_new = palm_step(
            kin.points @ R.T + t, kin.normals @ R.T, targets, target_normals,
            normal_weight=alpha, max_rotation=config.max_rotation_step,
        ) @ T
        q_new = q
        if not config.lock_fingers and gripper.n_joints:
            R, t = T_new[:3, :3], T_new[:3, 3]
            A, b = finger_rows(
                R, kin.points @ R.T + t, kin.normals, kin.J_points, kin.J_rotation,
                targets, target_normals, normal_weight=alpha,
            )
            step = np.where(gripper.revolute, config.max_revolute_step, np.inf)
            lower = np.maximum(gripper.lower - q, -step)
            upper = np.minimum(gripper.upper - q, step)
            q_new = gripper.clip(q + qp.solve(A, b, np.minimum(lower, 0.0), np.maximum(upper, 0.0)))
        kin_new = gripper.contact_kinematics(q_new, point_index)
        error_new = fitting_error(T_new, kin_new.points, kin_new.normals, targets, target_normals, alpha)
        if error_new > error:
            iterations -= 1
            break
        decrease = error - error_new
        T, q, kin, error = T_new, q_new, kin_new, error_new
        errors.append(error)
        if decrease <= threshold:
            break
    return IPFOResult(T, q, error, iterations, tuple(errors))

