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
        InvalidInputError: an argument of the wrong type (a gripper name instead of a
            :class:`Gripper`, ...), the pose is not a rigid transform, or ``q`` has the
            wrong size or lies outside the joint limits.
    """
    poses = _numbers(T_object_gripper, "T_object_gripper")
    joints = None if q is None else _numbers(q, "q")[None]
    return fit_many(gripper, obj, poses[None], joints, config)[0]


def _numbers(values, name: str) -> np.ndarray:
    """``values`` as a float array; InvalidInputError when they are not numbers."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be an array of numbers, got "
                                f"{type(values).__name__}") from None


def _check_types(gripper, obj, config) -> None:
    """Raise InvalidInputError naming the loader for a gripper, object or config of the wrong
    type."""
    for name, value, kind, hint in (
        ("gripper", gripper, Gripper, "isf.load_gripper(name or URDF path)"),
        ("obj", obj, ObjectSurface, "isf.load_object(path, array or shape:NAME)"),
    ):
        if not isinstance(value, kind):
            raise InvalidInputError(f"{name} must be an isf.{kind.__name__}, got "
                                    f"{type(value).__name__}: make one with {hint}")
    if config is not None and not isinstance(config, FitConfig):
        raise InvalidInputError(f"config must be an isf.FitConfig or None, got "
                                f"{type(config).__name__}: pass isf.FitConfig(**values) (or "
                                "FitConfig.from_dict(values))")


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
        InvalidInputError: an argument of the wrong type, a pose is not a rigid transform, or
            a joint vector has the wrong size or lies outside the joint limits.
    """
    _check_types(gripper, obj, config)
    poses = _numbers(T_object_gripper, "T_object_gripper")
    if poses.ndim == 2:
        poses = poses[None]
    if q is None:
        joints = [None] * len(poses)
    else:
        joints = _numbers(q, "q")
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
