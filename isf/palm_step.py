"""The IPFO palm step: closed-form least squares for the palm motion (paper eq. 5, 8, 10)."""

from __future__ import annotations

import numpy as np

from .se3 import cross, exp_so3

__all__ = ["palm_step"]


def palm_step(
    points: np.ndarray,
    normals: np.ndarray,
    targets: np.ndarray,
    target_normals: np.ndarray,
    *,
    normal_weight: float,
    max_rotation: float,
) -> np.ndarray:
    """Palm motion that best fits matched contact points onto the object.

    Solves :math:`x = (\\tilde A^T \\tilde A)^{-1} \\tilde A^T \\tilde b` (eq. 10) with
    point-to-plane rows :math:`a_i = [(p_i \\times n^q_i)^T, (n^q_i)^T]`,
    :math:`b_i = (q_i - p_i)^T n^q_i` (eq. 5) and normal-alignment rows
    :math:`[\\alpha (n^p_i \\times n^q_i)^T, 0]`, :math:`-\\alpha (n^p_i)^T n^q_i - \\alpha`
    (from eq. 8), linearised as :math:`R \\approx I + \\hat r`. Points are taken
    relative to their centroid, which leaves the minimiser unchanged and keeps the
    normal equations well conditioned. A rotation larger than ``max_rotation`` is
    scaled down (with its translation) to that angle.

    Args:
        points: contact points ``p_i``, object frame, shape (K, 3), metres.
        normals: their outward normals ``n^p_i``, object frame, shape (K, 3).
        targets: matched object points ``q_i``, shape (K, 3), metres.
        target_normals: object normals ``n^q_i`` at the targets, shape (K, 3).
        normal_weight: ``alpha``, metres (0 disables the normal rows).
        max_rotation: largest rotation of one step, radians.

    Returns:
        ``T_delta``, shape (4, 4): the motion to apply on the left of ``T_object_gripper``.
    """
    centre = points.mean(axis=0)
    offsets = points - centre
    A = np.concatenate([cross(offsets, target_normals), target_normals], axis=1)
    b = np.einsum("ij,ij->i", targets - points, target_normals)
    H = A.T @ A
    g = A.T @ b
    if normal_weight > 0.0:
        An = normal_weight * cross(normals, target_normals)
        bn = -normal_weight * (np.einsum("ij,ij->i", normals, target_normals) + 1.0)
        H[:3, :3] += An.T @ An
        g[:3] += An.T @ bn
    # A tiny ridge keeps directions the surfaces leave free (a pad sliding on a
    # plane) at zero motion instead of letting round-off move them.
    ridge = 1e-12 * max(np.trace(H), 1e-300)
    x = np.linalg.solve(H + ridge * np.eye(6), g)
    angle = float(np.linalg.norm(x[:3]))
    if angle > max_rotation:
        x *= max_rotation / angle
    R = exp_so3(x[:3])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = centre + x[3:] - R @ centre
    return T
