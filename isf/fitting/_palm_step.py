"""The IPFO palm step of many fits pair by pair: the reference's normal equations (paper eq. 5, 8,
10; :func:`isf.fitting.reference.palm_system`) solved by the engine's compiled palm motion
(:func:`isf.fitting.moment_kernels.palm_motion`). Tests compare the engine's moment form
(:class:`isf.fitting._moments.PairMoments`) with it.
"""

from __future__ import annotations

import numpy as np

from . import moment_kernels as kernels
from .reference import palm_system
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
    """Palm motions that best fit matched contact points onto the object, one per fit: eq. 10
    over the rows of :func:`isf.fitting.reference.palm_system` (about each fit's contact
    centroid), solved by :func:`palm_motions`.

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
    systems = [palm_system(points[rows], normals[rows], targets[rows], target_normals[rows],
                           normal_weight) for rows in segments.slices()]
    H, g, centre = (np.stack(parts) for parts in zip(*systems))
    return palm_motions(H, g, centre, max_rotation)


def palm_motions(H: np.ndarray, g: np.ndarray, centre: np.ndarray,
                 max_rotation: float) -> np.ndarray:
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
