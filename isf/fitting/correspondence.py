"""Correspondence matching (paper IV-B): nearest neighbours, outlier and duplicate filters.

:func:`match_many` matches the contact points of many fits with one nearest-neighbour
query; :func:`match` is the single-fit form.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.arrays import copy_into
from ..compiled.kernels import kernel
from ..object.surface import ObjectSurface
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
    if normals is not None and max_normal_angle < np.pi:
        compatible = np.einsum("ij,ij->i", normals, obj.normals[target]) <= -np.cos(max_normal_angle)
    else:
        compatible = np.ones(len(dist), dtype=bool)
    keep = filter_pairs(dist, target, groups.starts, segments.starts, float(outlier_factor),
                         float(outlier_floor), compatible, bool(reject_duplicates))
    source = np.flatnonzero(keep)
    return Correspondences(source, target[source], dist[source])


@kernel
def filter_pairs(dist, target, group_starts, fit_starts, outlier_factor, outlier_floor, compatible,
                  reject_duplicates):
    """The pairs :func:`match_many` keeps, a mask (M,): within the outlier threshold of their
    group (``group_starts``: first row of each group), ``compatible``, and, with
    ``reject_duplicates``, the nearest of the pairs of one fit (``fit_starts``) sharing a target
    (the first such pair when equally near)."""
    m = len(dist)
    keep = np.empty(m, dtype=np.bool_)
    ranked = np.empty(m)
    for g in range(len(group_starts)):
        b = group_starts[g + 1] if g + 1 < len(group_starts) else m
        keep_inliers(dist, group_starts[g], b, outlier_factor, outlier_floor, compatible, keep, ranked)
    if reject_duplicates and m:
        stamp = np.full(target.max() + 1, -1, np.int64)
        best_row = np.empty(len(stamp), np.int64)
        for f in range(len(fit_starts)):
            b = fit_starts[f + 1] if f + 1 < len(fit_starts) else m
            reject_duplicate_targets(dist, target, fit_starts[f], b, keep, best_row, stamp, f)
    return keep


@kernel
def keep_inliers(dist, a, b, outlier_factor, outlier_floor, compatible, keep, ranked):
    """``keep[a:b]``: the rows of one outlier group within ``max(outlier_factor * median,
    outlier_floor)`` of their match that are ``compatible``. ``ranked``: scratch of >= b - a."""
    threshold = outlier_threshold(dist, a, b, outlier_factor, outlier_floor, ranked)
    for i in range(a, b):
        keep[i] = dist[i] <= threshold and compatible[i]


@kernel
def outlier_threshold(dist, a, b, outlier_factor, outlier_floor, ranked):
    """``max(outlier_factor * median(dist[a:b]), outlier_floor)``, as numpy's median gives it
    (the mean of the two middle values for an even count); ``outlier_floor`` for no rows.
    ``ranked``: scratch of >= b - a.

    Most groups are settled by one counting pass: when more than half the distances lie
    within ``outlier_floor / outlier_factor`` (tested as ``outlier_factor * d <=
    outlier_floor``), so does the upper middle value, hence the median, and the floor is the
    threshold. Otherwise the middle values are selected (:func:`select`), not sorted."""
    n = b - a
    within = 0
    for i in range(a, b):
        within += outlier_factor * dist[i] <= outlier_floor
    if n == 0 or within > n // 2:
        return outlier_floor
    copy_into(ranked[:n], dist[a:b])
    upper = select(ranked, n, n // 2)  # leaves ranked[:n // 2] <= upper
    lower = upper
    if n % 2 == 0:
        lower = ranked[0]
        for i in range(1, n // 2):
            lower = max(lower, ranked[i])
    return max(outlier_factor * (0.5 * (lower + upper)), outlier_floor)


@kernel
def select(values, n, k):
    """The ``k``-th smallest of ``values[:n]`` (0-based, finite values), by quickselect with a
    three-way partition (linear time on average, also with many equal values). Reorders
    ``values[:n]`` so that ``values[:k] <= values[k] <= values[k + 1:n]``."""
    lo, hi = 0, n - 1
    while lo < hi:
        x, y, z = values[lo], values[(lo + hi) // 2], values[hi]  # the median of three as pivot
        pivot = max(min(x, y), min(max(x, y), z))
        less, i, more = lo, lo, hi  # [lo, less) < pivot, [less, i) == pivot, (more, hi] > pivot
        while i <= more:
            v = values[i]
            if v < pivot:
                values[i], values[less] = values[less], v
                less += 1
                i += 1
            elif v > pivot:
                values[i], values[more] = values[more], v
                more -= 1
            else:
                i += 1
        if k < less:
            hi = less - 1
        elif k > more:
            lo = more + 1
        else:
            return pivot
    return values[k]


@kernel
def reject_duplicate_targets(dist, target, a, b, keep, best_row, stamp, tag):
    """Among the kept rows ``a .. b - 1`` of one fit that share a target, keep only the nearest
    (the first of equally near ones). ``best_row``, ``stamp``: scratch with one entry per object
    point; ``tag``: a value ``stamp`` does not hold yet (a fresh one per call)."""
    for i in range(a, b):
        if not keep[i]:
            continue
        t = target[i]
        if stamp[t] != tag:
            stamp[t], best_row[t] = tag, i
        elif dist[i] < dist[best_row[t]]:
            keep[best_row[t]] = False
            best_row[t] = i
        else:
            keep[i] = False


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
