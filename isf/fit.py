"""Iterative surface fitting (paper Algorithm 2): :func:`fit` and :func:`fit_many`.

Both run the lockstep engine (:class:`isf.lockstep.LockstepFitter`, where the stop rule
is documented); :func:`fit` is one fit alone, :func:`fit_many` advances many together
(the same results as one :func:`fit` each, in a fraction of the time).
"""

from __future__ import annotations

import numpy as np

from .config import FitConfig
from .exceptions import InvalidInputError
from .gripper import Gripper
from .lockstep import LockstepFitter
from .object_surface import ObjectSurface
from .result import FitResult

__all__ = ["fit", "fit_many"]


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
    return fit_many(gripper, obj, np.asarray(T_object_gripper, dtype=float)[None],
                    None if q is None else np.asarray(q, dtype=float)[None], config)[0]


def fit_many(
    gripper: Gripper,
    obj: ObjectSurface,
    T_object_gripper: np.ndarray,
    q: np.ndarray | None = None,
    config: FitConfig | None = None,
) -> list[FitResult]:
    """Fit the gripper from B initial states at once (each fit as :func:`fit` would).

    Args:
        gripper: the gripper.
        obj: the object surface.
        T_object_gripper: initial palm poses, (B, 4, 4), metres.
        q: initial joints, (B, n_joints); default ``gripper.q_initial`` for every fit.
        config: fit parameters; default the paper's.

    Returns:
        one :class:`FitResult` per initial state, in order.

    Raises:
        InvalidInputError: a pose is not a rigid transform, or a joint vector has the
            wrong size or lies outside the joint limits.
    """
    T_batch = np.asarray(T_object_gripper, dtype=float)
    if T_batch.ndim != 3:
        T_batch = T_batch[None] if T_batch.ndim == 2 else T_batch
    poses = [_check_pose(T) for T in T_batch]
    if q is None:
        joints = [_check_joints(gripper, None) for _ in poses]
    else:
        q = np.asarray(q, dtype=float)
        q = q.reshape(len(poses), -1) if q.size == len(poses) * gripper.n_joints else q
        if len(q) != len(poses):
            raise InvalidInputError(f"got {len(poses)} poses but {len(q)} joint vectors: pass one per pose")
        joints = [_check_joints(gripper, qb) for qb in q]
    fitter = LockstepFitter(gripper, obj, config)
    for index, (T, qb) in enumerate(zip(poses, joints)):
        fitter.add(index, T, qb)
    results: dict[int, FitResult] = {}
    while fitter.n_active:
        results.update(fitter.step())
    return [results[i] for i in range(len(poses))]


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
