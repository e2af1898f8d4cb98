"""Features of a candidate start that transfer across objects and frames.

A start is a grasp centre ``c`` (object frame, metres) and a gripper orientation
``R_object_gripper``. Its features describe what ISF will meet there, measured in the
gripper's own frame and scale, never in absolute coordinates:

======================  ==============================================================
``approach_cos``        cosine between the approach axis and the inward surface normal
``closing_normal``      ``|closing axis . normal|`` (1: the jaws close along the normal)
``closing_extent``      extent of the piece along the closing axis through ``c``, in openings
``closing_offset``      distance from ``c`` to the middle of that extent, in openings
``approach_depth``      depth of the piece ahead of ``c`` along the approach axis, in openings
``surface_variation``   curvature at the opening's scale: ``l0 / (l0 + l1 + l2)`` of the
                        neighbours' covariance (0 flat, 1/3 isotropic)
``normal_spread``       ``1 - |mean normal|`` of the neighbours (0 flat, 1 folded)
``surface_distance``    distance from ``c`` to the nearest object point, in openings
``object_major``        the largest principal extent of the piece ``c`` lies on, in openings
``object_middle``       its middle principal extent, in openings
``object_minor``        its smallest principal extent, in openings
======================  ==============================================================

The *piece* of ``c`` is the connected part of the surface its nearest point lies on: points
closer than ``PIECE_GAP`` point spacings are joined. A mesh or a whole scan is one piece, so
these are the object's extents; on a scene of several objects the pieces are the objects apart
from one another (touching objects join), so they describe the object under ``c``, not the
whole table or another object further along the same line.

The gripper's *opening* ``w`` is the spread of its contact points along its closing axis at
``q_initial`` (metres); the *closing axis* is their first principal axis (gripper frame);
the *approach axis* is the declared ``<isf:gripper approach>`` in the gripper frame, or,
for a gripper without one, the contact points' last principal axis. Neighbourhoods are
balls of radius ``w / 2``; the closing and approach tubes have radius ``w / 4``.

:data:`FEATURE_VERSION` names this definition; a model file records it, and a model made
with another definition is refused.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from isf.samplers import grasp_centre
from isf.samplers.orientation import approach_direction

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

    from isf.gripper.model import Gripper
    from isf.object.surface import ObjectSurface

__all__ = [
    "FEATURE_NAMES",
    "FEATURE_VERSION",
    "GripperAxes",
    "ObjectDescriptors",
    "candidate_features",
    "gripper_axes",
    "gripper_sha256",
]

FEATURE_VERSION = "isf-learned-features/2"
FEATURE_NAMES = (
    "approach_cos",
    "closing_normal",
    "closing_extent",
    "closing_offset",
    "approach_depth",
    "surface_variation",
    "normal_spread",
    "surface_distance",
    "object_major",
    "object_middle",
    "object_minor",
)
_TUBE = 0.25  # tube radius, in openings
_BALL = 0.5  # neighbourhood radius, in openings
PIECE_GAP = 3.0
"""Points closer than this many point spacings (``ObjectSurface.spacing``) share a piece."""

MAJOR_PIECE_SHARE = 0.05
"""A piece holding at least this share of the surface's points is a major piece
(:attr:`ObjectDescriptors.major_pieces`); the smaller ones of a scene are stray points of the
sensor."""


def gripper_sha256(gripper: Gripper) -> str:
    """sha256 of the gripper as isf models it: joint limits, ``q_initial``, approach, and each
    contact surface's name, link, points and normals (rounded to 1 um and 1e-6).

    Two loads of the same tagged URDF give the same digest wherever the file lies; a change
    of tags, joint limits or surface sampling changes it.
    """
    digest = hashlib.sha256()

    def add(array) -> None:
        values = np.round(np.asarray(array, dtype=float), 6) + 0.0  # -0.0 -> 0.0
        digest.update(values.tobytes())

    add(gripper.lower)
    add(gripper.upper)
    add(gripper.q_initial)
    add([] if gripper.approach is None else gripper.approach)
    digest.update(str(gripper.palm_link).encode())
    for surface in gripper.surfaces:
        digest.update(f"{surface.name}\0{surface.link}\0".encode())
        add(surface.points)
        add(surface.normals)
    return digest.hexdigest()


@dataclass(frozen=True)
class GripperAxes:
    """The gripper's frame of reference for features (gripper frame).

    Attributes:
        centre: grasp centre (mean contact point at ``q_initial``), shape (3,), metres.
        approach: unit approach axis, shape (3,).
        closing: unit closing axis (first principal axis of the contact points), shape (3,).
        opening: spread of the contact points along ``closing``, metres.
    """

    centre: np.ndarray
    approach: np.ndarray
    closing: np.ndarray
    opening: float


def gripper_axes(gripper: Gripper) -> GripperAxes:
    """The :class:`GripperAxes` of ``gripper``."""
    points, _ = gripper.contact_points(gripper.q_initial)
    centre = np.asarray(grasp_centre(gripper), dtype=float)
    _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
    closing = axes[0]
    approach = approach_direction(gripper)
    if approach is None:
        approach = axes[-1]
    projection = (points - centre) @ closing
    opening = float(projection.max() - projection.min())
    return GripperAxes(centre=centre, approach=approach, closing=closing,
                       opening=max(opening, 1e-6))


@dataclass(eq=False)
class ObjectDescriptors:
    """What features need of one object for one gripper; local descriptors are computed on
    first use per point and kept.

    Attributes:
        points: object points, object frame, shape (N, 3), metres.
        normals: unit outward normals, shape (N, 3).
        opening: the gripper's opening, metres.
        tree: k-d tree of ``points``.
        piece: the piece each point lies on, shape (N,), indices into ``extents``.
        extents: each piece's principal extents, largest first, in openings, shape (P, 3).
        piece_points: each piece's points, P arrays of shape (N_k, 3), metres.
    """

    points: np.ndarray
    normals: np.ndarray
    opening: float
    tree: cKDTree
    piece: np.ndarray
    extents: np.ndarray
    piece_points: list[np.ndarray]
    _local: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._local = np.full((len(self.points), 2), np.nan)

    @classmethod
    def build(cls, obj: ObjectSurface, axes: GripperAxes) -> ObjectDescriptors:
        """Descriptors of ``obj`` at the scale of a gripper with ``axes``."""
        from scipy.sparse import coo_matrix  # here: listing the samplers loads this module
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree

        points = np.asarray(obj.points, dtype=float)
        tree = cKDTree(points)
        pairs = tree.query_pairs(PIECE_GAP * obj.spacing, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                           shape=(len(points), len(points)))
        _, piece = connected_components(graph, directed=False)
        parts = np.split(points[np.argsort(piece, kind="stable")], np.cumsum(np.bincount(piece))[:-1])
        extents = np.array([_principal_extents(part) for part in parts]) / axes.opening
        return cls(points=points, normals=np.asarray(obj.normals, dtype=float),
                   opening=axes.opening, tree=tree, piece=piece, extents=extents,
                   piece_points=parts)

    @property
    def major_pieces(self) -> int:
        """How many pieces hold at least :data:`MAJOR_PIECE_SHARE` of the points: 1 for a mesh
        or a scan of one object, the separate objects (or groups of touching ones) of a
        scene."""
        sizes = np.array([len(part) for part in self.piece_points])
        return int(np.count_nonzero(sizes >= MAJOR_PIECE_SHARE * len(self.points)))

    def local(self, index: np.ndarray) -> np.ndarray:
        """``surface_variation`` and ``normal_spread`` at object points ``index``, shape (M, 2).
        """
        index = np.asarray(index, dtype=int)
        missing = np.unique(index[np.isnan(self._local[index, 0])])
        if len(missing):
            neighbours = self.tree.query_ball_point(self.points[missing], _BALL * self.opening)
            counts = np.array([len(near) for near in neighbours])
            self._local[missing[counts < 4]] = 0.0
            full = counts >= 4
            if full.any():
                self._local[missing[full]] = self._local_descriptors(
                    missing[full], [near for near, ok in zip(neighbours, full) if ok])
        return self._local[index]

    def _local_descriptors(self, index: np.ndarray, neighbours: list[list[int]]) -> np.ndarray:
        """``surface_variation`` and ``normal_spread`` of points ``index`` from their (>= 4)
        neighbours, all at once: per-point sums by ``np.add.reduceat``, shape (M, 2)."""
        counts = np.array([len(near) for near in neighbours])
        flat = np.concatenate(neighbours).astype(int)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        offset = self.points[flat] - np.repeat(self.points[index], counts, axis=0)
        mean = np.add.reduceat(offset, starts, axis=0) / counts[:, None]
        second = np.add.reduceat(offset[:, :, None] * offset[:, None, :], starts, axis=0)
        covariance = second / counts[:, None, None] - mean[:, :, None] * mean[:, None, :]
        eigen = np.linalg.eigvalsh(covariance)  # ascending, (M, 3)
        variation = eigen[:, 0] / np.maximum(eigen.sum(axis=1), 1e-30)
        normal = np.add.reduceat(self.normals[flat], starts, axis=0) / counts[:, None]
        return np.column_stack([variation, 1.0 - np.linalg.norm(normal, axis=1)])


def _principal_extents(points: np.ndarray) -> np.ndarray:
    """Extents of ``points`` (shape (N, 3)) along their principal axes, largest first, (3,)."""
    centred = points - points.mean(axis=0)
    _, _, principal = np.linalg.svd(centred, full_matrices=False)
    projected = centred @ principal.T
    extents = projected.max(axis=0) - projected.min(axis=0)
    return np.sort(np.pad(extents, (0, 3 - len(extents))))[::-1]


_CHUNK = 1_000_000  # points x candidates per block of the tube computation


def _tube_range(points: np.ndarray, centres: np.ndarray, directions: np.ndarray,
                radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate, min and max of ``(p - c) . d`` over the points within ``radius`` of the
    line through ``c`` along ``d``; (0, 0) where none is.

    Args:
        points: object points, shape (N, 3), metres.
        centres: candidate centres, shape (M, 3), metres.
        directions: unit directions, shape (M, 3).
        radius: tube radius, metres.

    Returns:
        ``low`` and ``high``, each shape (M,), metres. Lines that coincide (the same centre
        and the same or the opposite direction, as the spins of a symmetric gripper give) are
        computed once; the others in blocks of matrix products.
    """
    sign = np.where(directions[np.arange(len(directions)),
                               np.argmax(np.abs(directions), axis=1)] < 0, -1.0, 1.0)
    lines = np.hstack([centres, sign[:, None] * directions])
    unique, line = np.unique(np.round(lines, 9), axis=0, return_inverse=True)
    first = np.zeros(len(unique), dtype=int)
    first[line.reshape(-1)[::-1]] = np.arange(len(lines))[::-1]
    c, d = centres[first], sign[first, None] * directions[first]
    low, high = np.zeros(len(unique)), np.zeros(len(unique))
    p2 = np.einsum("nk,nk->n", points, points)[:, None]
    step = max(1, _CHUNK // max(len(points), 1))
    for lo in range(0, len(unique), step):
        block = slice(lo, lo + step)
        cb, db = c[block], d[block]
        along = points @ db.T - np.einsum("mk,mk->m", cb, db)[None, :]  # (N, m)
        distance2 = p2 - 2.0 * (points @ cb.T) + np.einsum("mk,mk->m", cb, cb)[None, :]
        distance2 -= along**2  # squared distance from the line
        outside = distance2 > radius**2
        any_inside = ~outside.all(axis=0)
        along[outside] = np.inf  # in place: the blocks are the largest arrays of a plan's start
        low[block] = np.where(any_inside, along.min(axis=0), 0.0)
        along[outside] = -np.inf
        high[block] = np.where(any_inside, along.max(axis=0), 0.0)
    line = line.reshape(-1)
    flip = sign < 0  # the opposite of the computed direction: the range mirrored
    return np.where(flip, -high[line], low[line]), np.where(flip, -low[line], high[line])


def candidate_features(descriptors: ObjectDescriptors, axes: GripperAxes,
                       centres: np.ndarray, R_object_gripper: np.ndarray) -> np.ndarray:
    """Features of candidate starts (see the module docstring for their meaning).

    Args:
        descriptors: the object's :class:`ObjectDescriptors`.
        axes: the gripper's :class:`GripperAxes`.
        centres: grasp centres, object frame, shape (M, 3), metres.
        R_object_gripper: gripper orientations, shape (M, 3, 3).

    Returns:
        features, shape (M, len(FEATURE_NAMES)), ordered as :data:`FEATURE_NAMES`.
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    R = np.asarray(R_object_gripper, dtype=float).reshape(-1, 3, 3)
    w = descriptors.opening
    distance, nearest = descriptors.tree.query(centres)
    normal = descriptors.normals[nearest]
    approach = R @ axes.approach
    closing = R @ axes.closing
    piece = descriptors.piece[nearest]
    low, high, depth = np.zeros(len(centres)), np.zeros(len(centres)), np.zeros(len(centres))
    for k in np.unique(piece):
        on = piece == k
        points = descriptors.piece_points[k]
        low[on], high[on] = _tube_range(points, centres[on], closing[on], _TUBE * w)
        depth[on] = _tube_range(points, centres[on], approach[on], _TUBE * w)[1]
    columns = [
        -np.einsum("mk,mk->m", approach, normal),
        np.abs(np.einsum("mk,mk->m", closing, normal)),
        (high - low) / w,
        np.abs(0.5 * (high + low)) / w,
        np.maximum(depth, 0.0) / w,
        *descriptors.local(nearest).T,
        distance / w,
        *descriptors.extents[piece].T,
    ]
    return np.column_stack(columns)
