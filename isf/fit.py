"""Iterative surface fitting (paper Algorithm 2): :func:`fit`.

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

import numpy as np

from .config import FitConfig
from .correspondence import match
from .exceptions import InvalidInputError
from .finger_step import FingerStepQP
from .gripper import Gripper
from .ipfo import MatchedPairs, ipfo
from .object_surface import ObjectSurface
from .result import FitResult, FitStatus, IterationRecord

__all__ = ["fit"]


def fit(
    gripper: Gripper,
    obj: ObjectSurface,
    T_object_gripper: np.ndarray,
    q: np.ndarray | None = None,
    config: FitConfig | None = None,
) -> FitResult:
    """Fit the gripper's contact surfaces onto the object from one initial state.

    Args:
        gripper: the gripper (see :func:`isf.load_gripper`).
        obj: the object surface (see :func:`isf.load_object`).
        T_object_gripper: initial pose of the gripper frame (URDF root link) in
            the object frame, (4, 4), metres.
        q: initial joints, (n_joints,); default ``gripper.q_initial``.
        config: fit parameters; default :class:`FitConfig()` (the paper's).

    Returns:
        the :class:`FitResult`.

    Raises:
        InvalidInputError: the pose is not a rigid transform, or ``q`` has the
            wrong size or lies outside the joint limits.
    """
    started = time.perf_counter()
    config = FitConfig() if config is None else config
    T = _check_pose(T_object_gripper)
    q = _check_joints(gripper, q)
    qp = FingerStepQP(gripper.n_joints, config.finger_damping) if gripper.n_joints else None

    history: list[IterationRecord] = []
    status = FitStatus.MAX_ITERATIONS
    for level in reversed(range(config.levels)):
        index = np.flatnonzero(gripper.level_mask(level))
        max_iterations = max(1, config.max_iterations // 2**level)
        eps = 2**level * config.tolerance
        start, current_normals = _object_points(gripper, T, q, index)
        current = start
        displacement, eta, iteration = np.inf, 0.0, 0
        while not (1.0 - eps <= eta <= 1.0 + eps) and iteration < max_iterations:
            iteration += 1
            previous = displacement
            pairs = match(
                obj, current, outlier_factor=config.outlier_factor,
                outlier_floor=config.outlier_floor, reject_duplicates=config.reject_duplicates,
                normals=current_normals, max_normal_angle=config.max_normal_angle,
            )
            if len(pairs.source) < config.min_pairs:
                status = FitStatus.LOST_CONTACT
                break
            matched = MatchedPairs(gripper, index[pairs.source], obj.points[pairs.target],
                                   obj.normals[pairs.target])
            step = ipfo(matched, T, q, qp, config)
            T, q = step.T_object_gripper, step.q
            current, current_normals = _object_points(gripper, T, q, index)
            displacement = float(np.linalg.norm(current - start))
            eta = 1.0 if displacement <= 1e-12 else displacement / previous
            history.append(IterationRecord(
                level=level, iteration=iteration, mean_distance=step.mean_distance,
                error=step.error, n_pairs=len(matched), q=q.copy(), ipfo_errors=step.errors,
            ))
        if status is FitStatus.LOST_CONTACT:
            break
        if level == 0 and 1.0 - eps <= eta <= 1.0 + eps:
            status = FitStatus.CONVERGED
    return _final_result(gripper, obj, T, q, config, status, history, started)


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


def _object_points(gripper: Gripper, T: np.ndarray, q: np.ndarray,
                   index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Contact points ``index`` and their normals at ``(T, q)`` in the object frame, each (len(index), 3)."""
    points, normals = gripper.contact_points(q, index)
    return points @ T[:3, :3].T + T[:3, 3], normals @ T[:3, :3].T


def _final_result(gripper, obj, T, q, config, status, history, started) -> FitResult:
    """Score the final state on the finest level with fresh correspondences."""
    points, normals = gripper.contact_points(q)
    R, t = T[:3, :3], T[:3, 3]
    points = points @ R.T + t
    normals = normals @ R.T
    pairs = match(
        obj, points, outlier_factor=config.outlier_factor, outlier_floor=config.outlier_floor,
        reject_duplicates=config.reject_duplicates, normals=normals,
        max_normal_angle=config.max_normal_angle,
    )
    matched = MatchedPairs(gripper, pairs.source, obj.points[pairs.target], obj.normals[pairs.target])
    if len(matched):
        points_g, normals_g, _ = matched.evaluate(gripper.link_kinematics(q))
        d, c = matched.residuals(T, points_g, normals_g)  # c = (R n^p)^T n^q + 1
        mean_distance = float(np.abs(d).mean())
        misalignment = float(np.arccos(np.clip(1.0 - c, -1.0, 1.0)).mean())
        error = matched.error(T, points_g, normals_g, config.normal_weight)
    else:
        mean_distance = misalignment = error = float("inf")
    near, _ = obj.nearest(points)
    touching = near <= config.contact_distance
    surface_contact = {
        s.name: float(touching[gripper.point_surface == k].mean())
        for k, s in enumerate(gripper.surfaces)
    }
    return FitResult(
        T_object_gripper=T, q=q.copy(), joints=gripper.joints(q), mean_distance=mean_distance,
        normal_misalignment=misalignment, error=error, n_pairs=len(matched),
        contact_points=points[matched.point_index], object_points=matched.targets,
        surface_contact=surface_contact,
        iterations=len(history), status=status, history=tuple(history),
        time=time.perf_counter() - started,
    )
