"""Correspondence matching (paper IV-B): nearest neighbours, outlier and duplicate filters.

:func:`match_many` matches the contact points of many fits with one nearest-neighbour
query; :func:`match` is the single-fit form.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .object_surface import ObjectSurface
from .segments import Segments

__all__ = ["Correspondences", "match", "match_many"]


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


def match_many(
    obj: ObjectSurface,
    points: np.ndarray,
    segments: Segments,
    *,
    outlier_factor: float,
    outlier_floor: float,
    reject_duplicates: bool,
    normals: np.ndarray | None = None,
    max_normal_angle: float = np.pi,
    nearest: tuple[np.ndarray, np.ndarray] | None = None,
    outlier_groups: Segments | None = None,
) -> Correspondences:
    """Match contact points to their nearest object points and filter the pairs, per fit.

    A pair is an outlier when its distance exceeds both ``outlier_factor`` times
    the median distance of its group and ``outlier_floor``; the group is its fit, or a
    finer grouping given as ``outlier_groups`` (e.g. one per contact surface of each fit). With ``reject_duplicates``,
    when several contact points of one fit share an object point only the closest pair
    is kept (Zinsser et al., the paper's ref. [15]). With ``normals``, a pair whose
    contact normal is more than ``max_normal_angle`` away from the reversed object
    normal is dropped too (a pad overhanging an edge must not be pulled by the
    side face beyond it).

    Args:
        obj: the object surface.
        points: contact points of all fits, object frame, shape (M, 3), metres.
        segments: the fit of each point (points grouped by fit).
        outlier_factor: relative outlier threshold (times the median distance).
        outlier_floor: distances below this are never outliers, metres.
        reject_duplicates: apply the duplicate filter.
        normals: contact normals in the object frame, shape (M, 3), or None.
        max_normal_angle: normal compatibility threshold, radians.
        nearest: ``obj.nearest(points)`` when the caller has it already.
        outlier_groups: groups of consecutive points sharing one median (default ``segments``).

    Returns:
        the surviving pairs, sorted by query index (so still grouped by fit).
    """
    dist, target = obj.nearest(points) if nearest is None else nearest
    groups = segments if outlier_groups is None else outlier_groups
    medians = _group_medians(dist, groups)
    threshold = np.maximum(outlier_factor * medians, outlier_floor)
    keep = dist <= threshold[groups.ids]
    if normals is not None and max_normal_angle < np.pi:
        keep &= np.einsum("ij,ij->i", normals, obj.normals[target]) <= -np.cos(max_normal_angle)
    source = np.flatnonzero(keep)
    target, dist = target[source], dist[source]
    if reject_duplicates and len(source):
        fit = segments.ids[source]
        order = np.lexsort((dist, target, fit))
        first = np.ones(len(order), dtype=bool)
        first[1:] = (target[order[1:]] != target[order[:-1]]) | (fit[order[1:]] != fit[order[:-1]])
        keep = np.sort(order[first])
        source, target, dist = source[keep], target[keep], dist[keep]
    return Correspondences(source, target, dist)


def _group_medians(values: np.ndarray, groups: Segments) -> np.ndarray:
    """Median of ``values`` (M,) within each group, (G,) (one sort for all groups)."""
    order = np.lexsort((values, groups.ids))
    ranked = values[order]
    lower = groups.starts + (groups.counts - 1) // 2
    upper = groups.starts + groups.counts // 2
    return 0.5 * (ranked[lower] + ranked[upper])


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
    """:func:`match_many` for the points (M, 3) of one fit."""
    return match_many(obj, points, Segments.single(len(points)), outlier_factor=outlier_factor,
                      outlier_floor=outlier_floor, reject_duplicates=reject_duplicates,
                      normals=normals, max_normal_angle=max_normal_angle)
