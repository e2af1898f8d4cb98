"""Iterative surface fitting (paper Algorithm 2): :func:`fit` and :func:`fit_many`.

Both run the compiled lockstep engine (:class:`isf.fitting.engine.LockstepFitter`, where the
stop rule is documented); :func:`fit` is one fit alone, :func:`fit_many` advances many together
(the same results as one :func:`fit` each, in a fraction of the time). The paper's loops are
readable in the plain-Python reference the engine is tested against, whole fit by whole fit
(``tests/test_reference.py``): :func:`isf.fitting.reference.fit` (Algorithm 2) and
:func:`isf.fitting.reference.ipfo` (Algorithm 1); the planner's loop around ISF is
:func:`isf.planning.planner.plan` (Algorithm 3).
"""

from __future__ import annotations

import numpy as np

from ..config import FitConfig
from ..exceptions import InvalidInputError
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..result import FitResult
from .engine import LockstepFitter

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
    poses = np.asarray(T_object_gripper, dtype=float)
    if poses.ndim == 2:
        poses = poses[None]
    if q is None:
        joints = [None] * len(poses)
    else:
        joints = np.asarray(q, dtype=float)
        if joints.size == len(poses) * gripper.n_joints:
            joints = joints.reshape(len(poses), -1)
        if len(joints) != len(poses):
            raise InvalidInputError(
                f"got {len(poses)} poses but {len(joints)} joint vectors: pass one per pose")
    fitter = LockstepFitter(gripper, obj, config)
    for index, (T, qb) in enumerate(zip(poses, joints)):
        fitter.add(index, T, qb)  # checks the pose and the joints
    results: dict[int, FitResult] = {}
    while fitter.n_active:
        results.update(fitter.advance())
    return [results[i] for i in range(len(poses))]
