"""Correspondence matching (paper IV-B): nearest neighbours, outlier and duplicate filters."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .object_surface import ObjectSurface

__all__ = ["Correspondences", "match"]


class Correspondences(NamedTuple):
    """Matched pairs between contact points and object points.

    Attributes:
        source: indices of the matched contact points into the query array, shape (K,).
        target: indices of their object points into ``ObjectSurface.points``, shape (K,).
        distance: Euclidean distance of each pair, shape (K,), metres.
    """

    source: np.ndarray
    target: np.ndarray
    distance: np.ndarray


def match(
    obj: ObjectSurface,
    points: np.ndarray,
    *,
    outlier_factor: float,
    outlier_floor: float,
    reject_duplicates: bool,
    normals: np.ndarray | None = None,
    max_normal_angle: float = np.pi,
) -> Correspondences:
    """Match contact points to their nearest object points and filter the pairs.

    A pair is an outlier when its distance exceeds both ``outlier_factor`` times
    the median distance and ``outlier_floor``. With ``reject_duplicates``, when
    several contact points share one object point only the closest pair is kept
    (Zinsser et al., the paper's ref. [15]). With ``normals``, a pair whose
    contact normal is more than ``max_normal_angle`` away from the reversed object
    normal is dropped too (a pad overhanging an edge must not be pulled by the
    side face beyond it).

    Args:
        obj: the object surface.
        points: contact points in the object frame, shape (M, 3), metres.
        outlier_factor: relative outlier threshold (times the median distance).
        outlier_floor: distances below this are never outliers, metres.
        reject_duplicates: apply the duplicate filter.
        normals: contact normals in the object frame, shape (M, 3), or None.
        max_normal_angle: normal compatibility threshold, radians.

    Returns:
        the surviving pairs, sorted by contact-point index.
    """
    dist, target = obj.nearest(points)
    threshold = max(outlier_factor * float(np.median(dist)), outlier_floor)
    keep = dist <= threshold
    if normals is not None and max_normal_angle < np.pi:
        keep &= np.einsum("ij,ij->i", normals, obj.normals[target]) <= -np.cos(max_normal_angle)
    source = np.flatnonzero(keep)
    target, dist = target[source], dist[source]
    if reject_duplicates and len(source):
        order = np.lexsort((dist, target))
        first = np.ones(len(order), dtype=bool)
        first[1:] = target[order[1:]] != target[order[:-1]]
        keep = np.sort(order[first])
        source, target, dist = source[keep], target[keep], dist[keep]
    return Correspondences(source, target, dist)
