"""Re-closing: a gripper's joints moved, its palm held, until its contact surfaces lie on the
object again (:func:`reclose_joints`).

The centring (:mod:`isf.planning.centring`) slides a fitted grasp along the object's faces; where
the object's width changes along them (a bulged carton, a tapered bottle), the fit's joints leave
the contact surfaces off the object, or pressed into it, at the slid pose. Re-closing is the
finger half of ISF's step (the palm step held): point-to-plane distances to the nearest object
points, reduced by a bounded step of the joints.

Frames: ``T_object_gripper`` is the gripper root link in the object frame, metres.
"""

from __future__ import annotations

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ._box_qp import KKT_TOLERANCE, MAX_ROUNDS
from ._finger_step import bounded_steps

__all__ = ["reclose_joints"]

RECLOSE_ITERATIONS = 2
"""Gauss-Newton steps of :func:`reclose_joints` at most."""
RECLOSE_LEVEL = 2
"""Pyramid level of the contact points :func:`reclose_joints` matches (a quarter of them)."""
RECLOSE_REACH = 0.01
"""Contact points farther than this from the object (metres) do not pull the joints."""
RECLOSE_DAMPING = 1e-4
"""Weight of the rows that hold each joint where it is (metres per joint unit): a joint that
moves no matched point stays put, and the others are not disturbed measurably."""
RECLOSE_SETTLED = 1e-5
"""A step shorter than this (joint units) ends :func:`reclose_joints`."""


def reclose_joints(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
                   q: np.ndarray, iterations: int = RECLOSE_ITERATIONS) -> np.ndarray:
    """Joints that put the contact surfaces back on the object at a fixed palm pose.

    The finger half of ISF's step with the palm held: each contact point ``p`` (object frame;
    those of pyramid level ``RECLOSE_LEVEL``) is matched to its nearest object point ``o``
    with outward normal ``m``, and the joints move by the step, within the joint limits,
    that zeroes the point-to-plane distances ``m . (p - o)`` in the least-squares sense to
    first order, through the contact points' Jacobians, damped by ``RECLOSE_DAMPING``: the
    finger step's bounded solve (``isf.fitting._finger_step.bounded_steps``: the clipped
    minimiser for one joint, the active set for more).
    Points farther than ``RECLOSE_REACH`` from the object, or whose outward normal does not
    face the object's (a pad's back or rim), take no part.

    Args:
        gripper, obj: the gripper and the object surface (object frame).
        T_object_gripper: the palm pose, (4, 4).
        q: the joints to start from, (n_joints,).
        iterations: steps at most, each with fresh matches.

    Returns:
        the re-closed joints, (n_joints,), metres (prismatic) and radians (revolute); ``q``
        itself when no contact point is matched.
    """
    T = np.asarray(T_object_gripper, dtype=float)
    R, t = T[:3, :3], T[:3, 3]
    q = np.asarray(q, dtype=float).copy()
    mask = gripper.level_mask(RECLOSE_LEVEL)
    for _ in range(iterations):
        kin = gripper.contact_kinematics(q, mask)
        points = kin.points @ R.T + t
        distances, nearest = obj.nearest(points)
        m = obj.normals[nearest]
        facing = np.einsum("ij,ij->i", kin.normals @ R.T, m) < -0.5
        use = facing & (distances < RECLOSE_REACH)
        if not use.any():
            break
        residual = np.einsum("ij,ij->i", m[use], points[use] - obj.points[nearest[use]])
        A = np.einsum("ij,ijk->ik", m[use] @ R, kin.J_points[use])  # d(residual)/dq, (M, n)
        step, _ = bounded_steps((A.T @ A)[None], (-A.T @ residual)[None],
                                (gripper.lower - q)[None], (gripper.upper - q)[None],
                                RECLOSE_DAMPING ** 2, MAX_ROUNDS, KKT_TOLERANCE)
        q = np.clip(q + step[0], gripper.lower, gripper.upper)
        if np.abs(step).max() < RECLOSE_SETTLED:
            break
    return q
