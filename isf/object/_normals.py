"""Point-cloud normals: voxel downsampling, PCA estimation, consistent outward orientation.

* :func:`voxel_downsample` averages the points (and given normals) in each voxel;
* :func:`estimate_normals` takes the least-variance direction of each point's k nearest
  neighbours (PCA);
* :func:`orient_normals_mst` makes their signs consistent by propagation over a minimum
  spanning tree of the k-NN graph (weight ``1 - |n_i . n_j|``, Hoppe et al. 1992) and turns
  each connected part outward: away from its centroid, or towards a camera ``view``point;
* :func:`facing_away` marks the normals that face away from a camera (PCL's convention).
"""

from __future__ import annotations

import numpy as np

from ..search.voxel_grid import group_mean
from ._spanning_tree import tree_signs

__all__ = ["estimate_normals", "facing_away", "orient_normals_mst", "voxel_downsample"]


def voxel_downsample(
    points: np.ndarray, normals: np.ndarray | None, labels: np.ndarray, n_vox: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """Average the points, and the unit normals if given, of each voxel.

    Where opposite normals in one voxel (a thin wall) cancel, one member's normal is kept.

    Args:
        points: (N, 3) metres.
        normals: unit normals (N, 3), or None.
        labels: voxel of every point, (N,), integers in [0, n_vox), every voxel occupied.
        n_vox: number of voxels.

    Returns:
        (mean points (n_vox, 3), unit normals (n_vox, 3) or None).
    """
    means = group_mean(points, labels, n_vox)
    if normals is None:
        return means, None
    mean = group_mean(normals, labels, n_vox)
    length = np.linalg.norm(mean, axis=1)
    # Opposite normals in one voxel (a thin wall) cancel: keep one member's normal there.
    _, member = np.unique(labels, return_index=True)
    mean[length < 1e-6] = normals[member[length < 1e-6]]
    return means, mean / np.linalg.norm(mean, axis=1, keepdims=True)


def facing_away(points: np.ndarray, normals: np.ndarray, view: np.ndarray) -> np.ndarray:
    """Which normals point away from a camera.

    Args:
        points: (N, 3) metres. normals: (N, 3). view: camera position (3,), metres.

    Returns:
        (N,) bool, True where ``n . (view - p) < 0``.
    """
    return np.einsum("ij,ij->i", normals, view - points) < 0


def estimate_normals(points: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Unoriented unit normals: least-variance direction of each point's k-NN (PCA).

    Args:
        points: (N, 3) metres.
        neighbours: (N, k) indices of each point's k nearest neighbours (itself included).

    Returns:
        Unit normals (N, 3) of arbitrary sign.
    """
    local = points[neighbours]
    local = local - local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    _, vectors = np.linalg.eigh(cov)
    return vectors[:, :, 0]


def orient_normals_mst(
    points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray, view: np.ndarray | None = None
) -> np.ndarray:
    """Turn unoriented normals to one consistent, outward side.

    Signs propagate along a minimum spanning tree of the k-NN graph (weight ``1 - |n_i . n_j|``)
    from one seed per connected part: the point farthest from the part's centroid. Each part then
    faces outward: without ``view`` the seed's normal points away from the part's centroid; with
    ``view`` (camera position, (3,)) the part is flipped when most normals face away from the
    camera (a vote weighted by ``cos`` of the viewing angle).

    Args:
        points: (N, 3) metres. normals: (N, 3) unit. neighbours: (N, k) k-NN indices.

    Returns:
        Oriented unit normals, shape (N, 3).
    """
    n = len(points)
    edges = np.stack([np.repeat(np.arange(n), neighbours.shape[1]), neighbours.reshape(-1)], axis=1)
    cos = np.abs(np.einsum("ij,ij->i", normals[edges[:, 0]], normals[edges[:, 1]]))
    weights = 1.0 - cos + 1e-6  # scipy graphs drop zero-weight edges

    def farthest(labels: np.ndarray) -> np.ndarray:
        centre = group_mean(points, labels, int(labels.max()) + 1)
        d2 = np.einsum("ij,ij->i", points - centre[labels], points - centre[labels])
        order = np.lexsort((-d2, labels))
        return order[np.r_[0, np.flatnonzero(np.diff(labels[order])) + 1]]

    def flip_of(child: np.ndarray, parent: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", normals[child], normals[parent]) < 0

    sign, labels = tree_signs(n, edges, weights, farthest, flip_of)
    oriented = normals * sign[:, None]
    n_parts = int(labels.max()) + 1
    if view is None:
        seeds = farthest(labels)
        centre = group_mean(points, labels, n_parts)
        outward = np.einsum("ij,ij->i", oriented[seeds], points[seeds] - centre[labels[seeds]])
        vote = np.zeros(n_parts)
        vote[labels[seeds]] = outward
    else:
        sight = view - points
        sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-12)
        vote = np.bincount(
            labels, weights=np.einsum("ij,ij->i", oriented, sight), minlength=n_parts
        )
    oriented[(vote < 0)[labels]] *= -1.0
    return oriented
