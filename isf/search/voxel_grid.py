"""Cubic voxel grids over point sets: voxel labels and per-voxel means.

The grid is ``floor(p / size)`` in the frame of the points; only occupied voxels get a label.
Used to thin mesh samples and to downsample point clouds when loading objects.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InvalidInputError

__all__ = ["group_mean", "voxel_labels"]


def voxel_labels(points: np.ndarray, size: float) -> tuple[np.ndarray, int]:
    """Label each point with its voxel of the grid ``floor(p / size)``.

    Args:
        points: (N, 3) metres.
        size: voxel edge length, metres.

    Returns:
        (voxel label of every point (N,), number of occupied voxels).

    Raises:
        InvalidInputError: the grid over the points' bounding box has more than 2**62 voxels.
    """
    ijk = np.floor(points / size).astype(np.int64)
    ijk -= ijk.min(axis=0)
    dims = ijk.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) > 2.0**62:
        raise InvalidInputError(
            f"voxel_size={size:.3g} m is too small for this object: pass a larger voxel_size"
        )
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, labels = np.unique(keys, return_inverse=True)
    return labels.reshape(-1), int(labels.max()) + 1


def group_mean(values: np.ndarray, labels: np.ndarray, n_groups: int) -> np.ndarray:
    """Mean of the rows of ``values`` in each group.

    Args:
        values: (N, D).
        labels: group of every row, (N,), integers in [0, n_groups); every group non-empty.
        n_groups: number of groups.

    Returns:
        (n_groups, D) group means.
    """
    counts = np.bincount(labels, minlength=n_groups).astype(np.float64)
    sums = np.stack(
        [
            np.bincount(labels, weights=values[:, d], minlength=n_groups)
            for d in range(values.shape[1])
        ],
        axis=1,
    )
    return sums / counts[:, None]
