"""Triangle meshes to evenly spaced surface samples: cleaning, winding, area sampling, thinning.

* :func:`clean_mesh` merges vertices by position (ignoring the UV and normal seams that make
  textured OBJ files look open) and drops collapsed and repeated triangles;
* :func:`orient_bodies` gives each watertight body a consistent winding with positive volume,
  so its face normals point outward; open bodies keep the winding of the file;
* :func:`sample_by_area` draws random points uniformly by area (seeded);
* :func:`voxel_representatives` thins them to one per voxel, the sample nearest the voxel's
  mean, which spaces them evenly on the surface.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..exceptions import ObjectLoadError
from ..search.voxel_grid import group_mean
from ._spanning_tree import tree_signs

__all__ = [
    "clean_mesh",
    "orient_bodies",
    "sample_by_area",
    "triangle_normals",
    "voxel_representatives",
]

logger = logging.getLogger(__name__)


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group equal rows of a 2-D array.

    Returns:
        (one member index per group (G,), group of every row (N,)).
    """
    order = np.lexsort(rows.T[::-1])
    ranked = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = (ranked[1:] != ranked[:-1]).any(axis=1)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def clean_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices by position (ignores UV/normal seams); drop collapsed, repeated triangles
    and unreferenced vertices.

    Vertices merge when they agree to 8 decimals (in the units of ``vertices``).

    Args:
        vertices: (V, 3) float64.
        faces: (F, 3) int64 indices into ``vertices``.

    Returns:
        (vertices (V', 3), faces (F', 3)); both empty when no triangle survives.

    Raises:
        ObjectLoadError: a face index lies outside the vertex list.
    """
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ObjectLoadError(
            "the mesh has face indices outside its vertex list: repair or re-export the mesh"
        )
    rounded = np.round(vertices, 8) + 0.0  # + 0.0 turns -0.0 into 0.0 so both merge
    first, inverse = _unique_rows(rounded)
    faces = inverse[faces]
    faces = faces[
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    ]
    if len(faces) == 0:
        return vertices[:0], faces
    kept, _ = _unique_rows(np.sort(faces, axis=1))
    faces = faces[np.sort(kept)]
    used = np.flatnonzero(np.bincount(faces.reshape(-1), minlength=len(first)))
    remap = np.zeros(len(first), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[first[used]], remap[faces]


def orient_bodies(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Give each watertight body a consistent winding with positive volume; keep open bodies.

    A body is a set of triangles joined by manifold edges (shared by exactly two triangles); it
    is watertight when every edge of it is shared by exactly two triangles.

    Args:
        vertices: (V, 3) metres. faces: (F, 3) int64, as returned by :func:`clean_mesh`.

    Returns:
        (faces (F, 3) reoriented, closed (F,) bool: True where the face's body is watertight).
    """
    n_faces = len(faces)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)  # (3F, 2)
    keys = directed.min(axis=1) * len(vertices) + directed.max(axis=1)
    order = np.argsort(keys)
    ranked = keys[order]
    group = np.cumsum(np.r_[True, ranked[1:] != ranked[:-1]]) - 1
    ranked_count = np.bincount(group)[group]
    edge_count = np.empty(len(keys), dtype=np.int64)
    edge_count[order] = ranked_count
    # Adjacency over manifold edges (shared by exactly two triangles).
    shared = ranked_count == 2
    pairs = (order[shared] // 3).reshape(-1, 2)
    pair_starts = directed[order[shared], 0].reshape(-1, 2)

    if (pair_starts[:, 0] != pair_starts[:, 1]).all():  # winding already consistent
        graph = coo_matrix(
            (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_faces, n_faces)
        )
        body = connected_components(graph, directed=False)[1]
        sign = np.ones(n_faces, dtype=np.int8)
    else:

        def flip_of(child: np.ndarray, parent: np.ndarray) -> np.ndarray:
            # The same directed edge in both triangles means opposite windings.
            a = np.stack([faces[child], np.roll(faces[child], -1, axis=1)], axis=2)
            b = np.stack([faces[parent], np.roll(faces[parent], -1, axis=1)], axis=2)
            return (a[:, :, None, :] == b[:, None, :, :]).all(axis=3).any(axis=(1, 2))

        def first_face(labels: np.ndarray) -> np.ndarray:
            return np.unique(labels, return_index=True)[1]

        sign, body = tree_signs(n_faces, pairs, np.ones(len(pairs)), first_face, flip_of)
    closed_edge = edge_count.reshape(-1, 3) == 2
    n_body = int(body.max()) + 1
    closed = (
        np.bincount(body, weights=(~closed_edge.all(axis=1)).astype(np.float64), minlength=n_body)
        == 0
    )
    closed_face = closed[body]
    faces = faces.copy()
    flip = closed_face & (sign < 0)
    faces[flip] = faces[flip][:, ::-1]
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    volume = np.bincount(
        body, weights=np.einsum("ij,ij->i", v0, np.cross(v1, v2)), minlength=n_body
    )
    inverted = closed_face & (volume[body] < 0)
    faces[inverted] = faces[inverted][:, ::-1]
    logger.debug(
        "mesh: %d bodies, %d watertight, %d faces flipped",
        n_body,
        int(closed.sum()),
        int((flip ^ inverted).sum()),
    )
    return faces, closed_face


def triangle_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Twice the area and the unit normal (by winding) of every triangle.

    Args:
        vertices: (V, 3) metres. faces: (F, 3) int64.

    Returns:
        (double areas (F,) m^2, unit normals (F, 3); a zero vector for a collapsed triangle).
    """
    cross = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    double_area = np.linalg.norm(cross, axis=1)
    face_normals = cross / np.where(double_area > 0, double_area, 1.0)[:, None]
    return double_area, face_normals


def sample_by_area(
    vertices: np.ndarray, faces: np.ndarray, double_area: np.ndarray, n_samples: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Draw points uniformly by area on a triangle mesh.

    Args:
        vertices: (V, 3) metres. faces: (F, 3) int64.
        double_area: twice the area of each triangle, (F,), not all zero.
        n_samples: number of points to draw.
        seed: seed of the random generator (the same seed gives the same points).

    Returns:
        (points (n_samples, 3) metres, index of the triangle of each point (n_samples,)).
    """
    rng = np.random.default_rng(seed)
    tri = rng.choice(len(faces), size=n_samples, p=double_area / double_area.sum())
    r1, r2 = np.sqrt(rng.random(n_samples)), rng.random(n_samples)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    samples = np.einsum("nk,nkd->nd", bary, vertices[faces[tri]])
    return samples, tri


def voxel_representatives(samples: np.ndarray, labels: np.ndarray, n_vox: int) -> np.ndarray:
    """Pick, in every voxel, the sample nearest the mean of the voxel's samples.

    Args:
        samples: (N, 3) metres.
        labels: voxel of every sample, (N,), integers in [0, n_vox), every voxel occupied.
        n_vox: number of voxels.

    Returns:
        Indices into ``samples``, one per voxel in label order, shape (n_vox,); ties go to the
        lowest index.
    """
    centre = group_mean(samples, labels, n_vox)
    dist2 = np.einsum("ij,ij->i", samples - centre[labels], samples - centre[labels])
    best = np.full(n_vox, np.inf)
    np.minimum.at(best, labels, dist2)
    candidates = np.flatnonzero(dist2 == best[labels])
    _, first = np.unique(labels[candidates], return_index=True)
    return candidates[first]
