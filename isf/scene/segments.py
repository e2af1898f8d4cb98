"""Smooth, convex pieces of an unsegmented scene surface, and how many of them a grasp touches.

A grasp whose contact surfaces rest on two different objects (two boxes side by side) fits well
and may even be collision-free, but lifts neither object reliably. isf does not segment a scene
into objects; it splits the observed surface where no single object's surface is likely to
continue, by the locally convex connected patches (LCCP) criterion of Stein et al., "Object
Partitioning using Local Convexity" (CVPR 2014), on supervoxels:

1. **Supervoxels.** The points are binned into cubes of :data:`SUPERVOXEL` (8 mm); each cube's
   points form a supervoxel with their mean position and mean normal. :data:`REFINEMENTS`
   rounds then move every point to whichever supervoxel of its surface neighbours fits it best,
   by distance to the centre (in supervoxel sizes, squared) plus :data:`NORMAL_WEIGHT` times
   ``1 - cos`` of the angle between the normals. Where two surfaces meet, the points of each
   gather in supervoxels of their own instead of supervoxels that straddle the fold, so a
   supervoxel's normal is its own surface's even where the point normals blur across the fold.
2. **Adjacency.** Two supervoxels are adjacent when a point of one lies within
   :data:`NEIGHBOUR_GAPS` point spacings of a point of the other (a wider gap is a gap between
   objects).
3. **Convexity.** With centres ``x_a, x_b``, normals ``n_a, n_b`` and ``d`` the unit vector from
   ``x_b`` to ``x_a``, the connection is convex when ``(n_a - n_b) . d >= 0`` (round a box's
   corner) and concave when the normals lean towards each other; a concave connection whose
   normals differ by less than :data:`CONCAVITY_TOLERANCE` still joins (noise on a flat
   surface). A convex connection also has to pass LCCP's *sanity criterion*: ``d`` must not run
   along the fold line ``n_a x n_b``; the smallest angle allowed between them rises from 0 to
   :data:`SANITY_ANGLE` as the normals differ more (a sigmoid centred on 25 degrees). That cuts
   the connections that follow a concave crease, where ``d`` has no component across the fold
   and the convexity test alone is decided by noise.
4. **Pieces.** The pieces are the connected components of the joined supervoxels; a piece
   covering less than one supervoxel face (fewer than ``(SUPERVOXEL / spacing)**2`` points: a
   crease strip, a few flying pixels) joins its largest adjacent piece, so it joins one piece
   and never bridges two.

Where two objects meet (a can against a box, a box beside a lower box, a board leaning on a
box) the surface folds inward and they fall apart. A concave fold of one object splits it too
(a power drill's handle from its body and its battery), and a thin, flat object (scissors
lying flat, a few hundred points) breaks into small pieces. Objects whose visible surfaces
continue each other smoothly stay one piece: the tops of two boxes of the same height pressed
together, two side faces flush in one plane, and in some views parallel faces offset by a
ledge of a few millimetres, which the depth noise and the normal estimation smooth away. From
a depth image they cannot be told apart at this resolution.

A grasp *touches* a piece with a contact surface when most of that surface's points within
the contact distance of the scene lie nearest that piece's points; :meth:`SceneSegments.touched`
counts the pieces touched by all of a grasp's contact surfaces together.

Frames: every point and pose is in the scene frame (:mod:`isf.scene.loading`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..exceptions import InvalidInputError
from ..gripper.model import Gripper
from ..search.voxel_grid import voxel_labels

__all__ = [
    "CONCAVITY_TOLERANCE",
    "NEIGHBOUR_GAPS",
    "NORMAL_WEIGHT",
    "REFINEMENTS",
    "SANITY_ANGLE",
    "SUPERVOXEL",
    "SceneSegments",
    "segment_surface",
]

NEIGHBOUR_GAPS = 2.5
"""Neighbouring surface points lie within this many point spacings of each other."""

SUPERVOXEL = 0.008
"""Edge of the cubes that seed the supervoxels, metres (at least 3 point spacings)."""

NORMAL_WEIGHT = 8.0
"""Weight of ``1 - cos(normal angle)`` against the squared distance (in supervoxel sizes) when a
point picks its supervoxel: a 30 degree difference costs as much as a 1 supervoxel distance."""

REFINEMENTS = 3
"""Rounds in which points move to the best-fitting supervoxel of their neighbours."""

CONCAVITY_TOLERANCE = 10.0
"""Concave connections whose normals differ by less than this still join, degrees."""

SANITY_ANGLE = 60.0
"""Largest smallest-angle the sanity criterion asks between a connection and the fold line of
its normals, degrees (reached when the normals differ by much more than 25 degrees)."""

_NEIGHBOURS = 10
_SANITY_CENTRE, _SANITY_SLOPE = 25.0, 0.25  # degrees, 1/degree: LCCP's sigmoid


class _Supervoxels(NamedTuple):
    """Supervoxels of a surface.

    Attributes:
        labels: supervoxel of each point, (N,), 0 .. M-1.
        centres: mean position of each, (M, 3) metres.
        normals: unit mean normal of each, (M, 3).
    """

    labels: np.ndarray
    centres: np.ndarray
    normals: np.ndarray


def segment_surface(points: np.ndarray, normals: np.ndarray, spacing: float) -> np.ndarray:
    """Label the points of a scene surface with their piece (see the module docs).

    Args:
        points: (N, 3) metres. normals: unit normals (N, 3), facing the cameras.
        spacing: typical distance between neighbouring points, metres.

    Returns:
        (N,) piece labels, 0 .. P-1, numbered by decreasing size.

    Raises:
        InvalidInputError: points and normals are not both (N, 3), or spacing is not > 0.
    """
    points, normals = np.asarray(points, dtype=float), np.asarray(normals, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise InvalidInputError(f"segment_surface needs points and normals of one shape (N, 3), "
                                f"got {points.shape} and {normals.shape}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise InvalidInputError(f"segment_surface needs a point spacing > 0 in metres, "
                                f"got {spacing!r}")
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    _, neighbours = cKDTree(points).query(points, k=min(_NEIGHBOURS, n),
                                          distance_upper_bound=NEIGHBOUR_GAPS * spacing)
    neighbours = neighbours.reshape(n, -1)
    neighbours = np.where(neighbours < n, neighbours, np.arange(n)[:, None])  # none: itself
    size = max(SUPERVOXEL, 3.0 * spacing)
    voxels = _supervoxels(points, normals, neighbours, size)
    m = len(voxels.centres)
    a, b = _adjacent_pairs(voxels.labels, neighbours, m)
    join = _joins(voxels, a, b)
    graph = coo_matrix((np.ones(int(join.sum())), (a[join], b[join])), shape=(m, m))
    _, piece = connected_components(graph, directed=False)
    piece = _absorb_small(piece, voxels.labels, a, b, (size / spacing) ** 2)
    labels = piece[voxels.labels]
    sizes = np.bincount(labels)
    rank = np.zeros(len(sizes), dtype=np.int64)
    rank[np.argsort(-sizes, kind="stable")] = np.arange(len(sizes))
    return rank[labels]


def _supervoxels(points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray,
                 size: float) -> _Supervoxels:
    """Supervoxels of a surface (step 1 of the module docs).

    Args:
        points: (N, 3) metres. normals: unit normals (N, 3).
        neighbours: each point's surface neighbours, (N, K) indices (itself where it has fewer).
        size: edge of the seeding cubes, metres.
    """
    labels, m = voxel_labels(points, size)
    own = np.arange(len(points))
    for round_ in range(REFINEMENTS + 1):
        count = np.maximum(np.bincount(labels, minlength=m), 1)
        centres = _sums(points, labels, m) / count[:, None]
        mean_normals = _sums(normals, labels, m)
        mean_normals /= np.maximum(np.linalg.norm(mean_normals, axis=1), 1e-12)[:, None]
        if round_ == REFINEMENTS:
            break
        candidates = labels[neighbours]
        offset = points[:, None, :] - centres[candidates]
        cost = np.einsum("nkj,nkj->nk", offset, offset) / size**2 + NORMAL_WEIGHT * (
            1.0 - np.einsum("nj,nkj->nk", normals, mean_normals[candidates]))
        labels = candidates[own, cost.argmin(axis=1)]
    used, labels = np.unique(labels, return_inverse=True)
    return _Supervoxels(labels.reshape(-1), centres[used], mean_normals[used])


def _sums(values: np.ndarray, labels: np.ndarray, m: int) -> np.ndarray:
    """Sum of ``values`` (N, 3) over each label 0 .. m-1, (m, 3)."""
    return np.stack([np.bincount(labels, values[:, k], minlength=m) for k in range(3)], axis=1)


def _adjacent_pairs(labels: np.ndarray, neighbours: np.ndarray,
                    m: int) -> tuple[np.ndarray, np.ndarray]:
    """The adjacent supervoxel pairs ``(a, b)``, ``a < b``, each once (two (E,) arrays)."""
    a = np.repeat(labels, neighbours.shape[1])
    b = labels[neighbours.ravel()]
    cross = a != b
    keys = np.unique(np.minimum(a[cross], b[cross]) * m + np.maximum(a[cross], b[cross]))
    return keys // m, keys % m


def _joins(voxels: _Supervoxels, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each adjacent pair joins: convex (or nearly flat) and sane (step 3), (E,)."""
    na, nb = voxels.normals[a], voxels.normals[b]
    d = voxels.centres[a] - voxels.centres[b]
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    beta = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", na, nb), -1.0, 1.0)))
    convex = np.einsum("ij,ij->i", na - nb, d) >= 0.0
    fold = np.cross(na, nb)
    fold_length = np.linalg.norm(fold, axis=1)
    along = np.abs(np.einsum("ij,ij->i", fold, d)) / np.maximum(fold_length, 1e-12)
    theta = np.degrees(np.arccos(np.clip(along, 0.0, 1.0)))
    least = SANITY_ANGLE / (1.0 + np.exp(-_SANITY_SLOPE * (beta - _SANITY_CENTRE)))
    sane = (theta >= least) | (fold_length < 1e-9)
    return (convex & sane) | (beta < CONCAVITY_TOLERANCE)


def _absorb_small(piece: np.ndarray, labels: np.ndarray, a: np.ndarray, b: np.ndarray,
                  smallest: float) -> np.ndarray:
    """Join every piece of fewer than ``smallest`` points to its largest adjacent piece.

    Args:
        piece: piece of each supervoxel, (M,). labels: supervoxel of each point, (N,).
        a, b: the adjacent supervoxel pairs, (E,) each.
        smallest: points a piece needs to stay on its own.

    Returns:
        the new piece of each supervoxel, (M,). Each small piece points to one larger piece (ties
        broken by label), so the joins form trees with one root each: no two pieces of
        ``smallest`` points or more end up joined.
    """
    count = int(piece.max()) + 1
    size = np.bincount(piece[labels], minlength=count)
    pa, pb = piece[a], piece[b]
    cross = pa != pb
    src = np.concatenate([pa[cross], pb[cross]])
    dst = np.concatenate([pb[cross], pa[cross]])
    larger = (size[dst] > size[src]) | ((size[dst] == size[src]) & (dst > src))
    src, dst = src[larger & (size[src] < smallest)], dst[larger & (size[src] < smallest)]
    order = np.lexsort((-size[dst], src))
    _, first = np.unique(src[order], return_index=True)
    src, dst = src[order][first], dst[order][first]
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(count, count))
    _, merged = connected_components(graph, directed=False)
    return merged[piece]


@dataclass(frozen=True, eq=False)
class SceneSegments:
    """A scene surface's pieces, with a search for the piece nearest a point.

    Attributes:
        labels: piece of each surface point, (N,).
        count: number of pieces.
    """

    labels: np.ndarray
    count: int
    _tree: cKDTree

    @classmethod
    def of(cls, points: np.ndarray, normals: np.ndarray, spacing: float) -> SceneSegments:
        """The pieces of a surface (:func:`segment_surface`)."""
        labels = segment_surface(points, normals, spacing)
        return cls(labels, int(labels.max()) + 1 if len(labels) else 0, cKDTree(points))

    def touched(self, gripper: Gripper, T_scene_gripper: np.ndarray, q: np.ndarray,
                contact_distance: float) -> int:
        """How many pieces the grasp's contact surfaces rest on (0 when none touches).

        Args:
            gripper: the gripper.
            T_scene_gripper: the grasp's palm pose in the scene frame, (4, 4).
            q: its joints, (n_joints,).
            contact_distance: a contact point within this distance of a surface point touches
                it, metres.
        """
        points, _ = gripper.contact_points(np.asarray(q, dtype=float))
        points = points @ T_scene_gripper[:3, :3].T + T_scene_gripper[:3, 3]
        dist, nearest = self._tree.query(points, distance_upper_bound=contact_distance)
        pieces = set()
        for k in range(len(gripper.surfaces)):
            on = (gripper.point_surface == k) & np.isfinite(dist)
            if on.any():
                pieces.add(int(np.bincount(self.labels[nearest[on]]).argmax()))
        return len(pieces)
