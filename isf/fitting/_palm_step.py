"""The IPFO palm step: closed-form least squares for the palm motion (paper eq. 5, 8, 10).

:func:`palm_steps` solves the step of many fits at once (one 6x6 system per fit, the
pairs of all fits concatenated); :func:`palm_step` is the single-fit form.
"""

from __future__ import annotations

import numpy as np

from . import moment_kernels as kernels
from ..se3 import cross
from .segments import Segments

__all__ = ["palm_motions", "palm_step", "palm_steps"]


def palm_steps(
    points: np.ndarray,
    normals: np.ndarray,
    targets: np.ndarray,
    target_normals: np.ndarray,
    segments: Segments,
    *,
    normal_weight: float,
    max_rotation: float,
) -> np.ndarray:
    """Palm motions that best fit matched contact points onto the object, one per fit.

    Solves :math:`x = (\\tilde A^T \\tilde A)^{-1} \\tilde A^T \\tilde b` (eq. 10) with
    point-to-plane rows :math:`a_i = [(p_i \\times n^q_i)^T, (n^q_i)^T]`,
    :math:`b_i = (q_i - p_i)^T n^q_i` (eq. 5) and normal-alignment rows
    :math:`[\\alpha (n^p_i \\times n^q_i)^T, 0]`, :math:`-\\alpha (n^p_i)^T n^q_i - \\alpha`
    (from eq. 8), linearised as :math:`R \\approx I + \\hat r`. Points are taken
    relative to their fit's centroid, which leaves the minimiser unchanged and keeps the
    normal equations well conditioned. A rotation larger than ``max_rotation`` is
    scaled down (with its translation) to that angle.

    Args:
        points: contact points ``p_i``, object frame, shape (K, 3), metres.
        normals: their outward normals ``n^p_i``, object frame, shape (K, 3).
        targets: matched object points ``q_i``, shape (K, 3), metres.
        target_normals: object normals ``n^q_i`` at the targets, shape (K, 3).
        segments: which fit each pair belongs to (pairs grouped by fit, B fits).
        normal_weight: ``alpha``, metres (0 disables the normal rows).
        max_rotation: largest rotation of one step, radians.

    Returns:
        ``T_delta``, shape (B, 4, 4): the motions to apply on the left of each ``T_object_gripper``.
    """
    centre = segments.mean(points)
    offsets = points - centre[segments.ids]
    a = np.concatenate([cross(offsets, target_normals), target_normals], axis=1)
    b = np.einsum("ij,ij->i", targets - points, target_normals)
    H = segments.sum(a[:, :, None] * a[:, None, :])
    g = segments.sum(a * b[:, None])
    if normal_weight > 0.0:
        an = normal_weight * cross(normals, target_normals)
        bn = -normal_weight * (np.einsum("ij,ij->i", normals, target_normals) + 1.0)
        H[:, :3, :3] += segments.sum(an[:, :, None] * an[:, None, :])
        g[:, :3] += segments.sum(an * bn[:, None])
    return palm_motions(H, g, centre, max_rotation)


def palm_motions(H: np.ndarray, g: np.ndarray, centre: np.ndarray, max_rotation: float) -> np.ndarray:
    """Solve the palm normal equations ``H x = g`` (B, 6, 6), (B, 6) for the twists
    ``x = [r, u]`` about the centroids ``centre`` (B, 3); returns ``T_delta`` (B, 4, 4).

    A rotation larger than ``max_rotation`` (radians) is scaled down, with its translation.
    A ridge of ``1e-12 trace(H)`` keeps the directions the surfaces leave free (a pad sliding
    on a plane) at zero motion instead of letting round-off move them.
    """
    as_float = (np.ascontiguousarray(a, dtype=float) for a in (H, g, centre))
    return kernels.palm_motions(*as_float, float(max_rotation))


def palm_step(
    points: np.ndarray,
    normals: np.ndarray,
    targets: np.ndarray,
    target_normals: np.ndarray,
    *,
    normal_weight: float,
    max_rotation: float,
) -> np.ndarray:
    """The palm step of one fit (see :func:`palm_steps`); returns ``T_delta``, shape (4, 4)."""
    one = Segments.single(len(points))
    return palm_steps(points, normals, targets, target_normals, one,
                      normal_weight=normal_weight, max_rotation=max_rotation)[0]
