"""Compiled pieces of the collision repair's clearance rows (:mod:`isf.repair.clearance`).

* :func:`deepest_rows`: the rows a repair step uses, the most violated ones of each geometry
  element;
* :func:`undecided`: which rows whose violation is only bounded may still be among them, or
  be the most violated row of all (the others need not be computed);
* :func:`sample_rows`: the clearance rows of gripper samples against the object's tangent
  planes (documented at ``isf.repair.clearance.ClearanceRepair._sample_rows``), in one call.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..collision.surface_distance import plane_estimates
from ..collision.voxels import boxes_clear, points_distance_below
from ..compiled.arrays import copy_into
from ..compiled.kernels import kernel
from ..fitting.engine_kernel import plane_distance
from ..search.nearest import SearchArrays, nearest_with_guesses

__all__ = ["DensePlanes", "RowLimits", "deepest_rows", "sample_rows", "undecided"]


class RowLimits(NamedTuple):
    """Which clearance rows :func:`sample_rows` keeps."""

    n_elements: int
    """The gripper's geometry elements (as for :func:`deepest_rows`)."""
    activation: float
    """Rows more than this below their floor are never used, m (as for :func:`deepest_rows`)."""
    max_rows: int
    """Rows used per element at most (as for :func:`deepest_rows`)."""
    slack: float
    """Rounding allowance of the violation bounds, m."""
    reach: float
    """Samples farther than this from the object and outside it get no row, m."""


class DensePlanes(NamedTuple):
    """The dense tangent planes of the object (:class:`isf.collision.surface_distance.TangentPlanes`),
    P points."""

    points: np.ndarray
    """(P, 3) float64, m."""
    normals: np.ndarray
    """Outward unit normals, (P, 3) float64."""
    tree: SearchArrays
    """Their search (:attr:`isf.search.nearest.NearestPoints.tree`)."""
    neighbours: int
    """The tangent planes of an estimate (at most P)."""


@kernel
def deepest_rows(violation, element, n_elements, activation, max_rows):
    """Rows within ``activation`` of their floor, at most ``max_rows`` per element.

    Args:
        violation: ``floor - height`` of every row candidate, (M,), metres.
        element: its geometry element, (M,) integers in ``[0, n_elements)``.
        n_elements: number of elements.
        activation: a row with ``violation > -activation`` is a candidate, metres.
        max_rows: candidates kept per element (the most violated ones).

    Returns:
        indices of the kept rows (K,), by element, then most violated first, then by index.
    """
    n_kept = np.zeros(n_elements, np.int64)
    kept = np.empty((n_elements, max_rows), np.int64)  # per element, most violated first
    for i in range(len(violation)):
        v = violation[i]
        if not v > -activation:
            continue
        e = element[i]
        n = n_kept[e]
        if n == max_rows and not v > violation[kept[e, n - 1]]:
            continue
        slot = min(n, max_rows - 1)  # insert after the rows at least as violated (earlier index)
        while slot > 0 and violation[kept[e, slot - 1]] < v:
            kept[e, slot] = kept[e, slot - 1]
            slot -= 1
        kept[e, slot] = i
        n_kept[e] = min(n + 1, max_rows)
    out = np.empty(n_kept.sum(), np.int64)
    n = 0
    for e in range(n_elements):
        copy_into(out[n:n + n_kept[e]], kept[e, :n_kept[e]])
        n += n_kept[e]
    return out


@kernel
def undecided(bound, bound_element, violation, element, n_elements, activation, max_rows, slack):
    """Which rows of unknown violation may still be used, given rows whose violation is known.

    A row is decided (unused) when its violation, at most ``bound``, is below the ``max_rows``
    known ones of its element, or is at most ``-activation`` and below some known one (so it is
    neither a row :func:`deepest_rows` keeps nor the largest violation).

    Args:
        bound: upper bounds of the unknown violations, (U,), metres.
        bound_element: their elements, (U,).
        violation, element: the known violations (K,) and their elements (K,).
        n_elements, activation, max_rows: as for :func:`deepest_rows`.
        slack: rounding allowance on ``bound``, metres.

    Returns:
        mask (U,) of the rows still undecided.
    """
    top = np.full((n_elements, max_rows), -np.inf)  # per element, the largest known, descending
    largest = -np.inf
    for i in range(len(violation)):
        v, e = violation[i], element[i]
        largest = max(largest, v)
        if v > top[e, max_rows - 1]:
            slot = max_rows - 1
            while slot > 0 and top[e, slot - 1] < v:
                top[e, slot] = top[e, slot - 1]
                slot -= 1
            top[e, slot] = v
    out = np.empty(len(bound), np.bool_)
    for i in range(len(bound)):
        b = bound[i] + slack
        out[i] = not (b < top[bound_element[i], max_rows - 1] or (b <= -activation and b < largest))
    return out


@kernel
def sample_rows(world, guess, floor, element, known_violation, known_element, limits, obj, voxels,
                planes, resampled):
    """The clearance rows of gripper samples against the object's tangent planes (documented at
    ``isf.repair.clearance.ClearanceRepair._sample_rows``).

    Args:
        world, floor, element: the samples (M, 3) (object frame), their floors (M,), metres,
            and geometry elements (M,).
        guess: an object point near each sample to start its search from (M,), -1 for none
            (e.g. its nearest point one repair step before); it never changes an answer.
        known_violation, known_element: the state's other rows (K,).
        limits: the rows kept (:class:`RowLimits`).
        obj: the object's points, normals (N, 3) and :attr:`isf.search.nearest.NearestPoints.tree`.
        voxels: :func:`isf.collision.voxels.kernel_arrays` of the object's voxels.
        planes: the dense tangent planes (:class:`DensePlanes`).
        resampled: the dense planes are not the object's own points.

    Returns:
        (indices (R,) of the samples kept, their plane normals (R, 3), their violations (R,),
        the nearest object point of every sample (M,), -1 for those not searched: beyond reach
        and, by the voxels, outside).
    """
    obj_points, obj_normals, obj_tree = obj
    n_elements, activation, max_rows = limits.n_elements, limits.activation, limits.max_rows
    slack, reach = limits.slack, limits.reach
    m = len(world)
    outside = np.zeros(m, np.bool_)
    look = np.ones(m, np.bool_)
    table, gaps, lo, size = voxels.table, voxels.gaps, voxels.lo, voxels.size
    if voxels.present:  # outside by the voxels and beyond reach by their distance bound: no row
        outside = boxes_clear(table, lo, size, world, world)
        below = points_distance_below(gaps, lo, size, world)
        for i in range(m):
            look[i] = not outside[i] or below[i] < reach
    dist, nearest = np.full(m, np.inf), np.full(m, -1, np.int64)
    rows = np.flatnonzero(look)
    d, n = nearest_with_guesses(world[rows], guess[rows], reach * reach, obj_points, obj_tree)
    for k in range(len(rows)):
        dist[rows[k]], nearest[rows[k]] = d[k], n[k]
    far = np.flatnonzero((nearest < 0) & ~outside)  # beyond reach, maybe inside
    if len(far):
        d, n = nearest_with_guesses(world[far], guess[far], np.inf, obj_points, obj_tree)
        for k in range(len(far)):
            dist[far[k]], nearest[far[k]] = d[k], n[k]
    close = np.empty(m, np.int64)
    lower = np.empty(m)
    n_close = 0
    for i in range(m):
        if nearest[i] < 0:
            continue
        h = plane_distance(world, i, obj_points, obj_normals, nearest[i])
        if dist[i] < reach or h < 0.0:
            close[n_close], lower[n_close] = i, h
            n_close += 1
    close, lower = close[:n_close], lower[:n_close]
    kept_world = world[close]
    plane_points, plane_normals, plane_tree, k = (planes.points, planes.normals, planes.tree,
                                                  planes.neighbours)
    if resampled:  # the plane of the nearest dense point, one of the k
        # the dense points begin with the object's own: its nearest point bounds the search
        _, first = nearest_with_guesses(kept_world, nearest[close], np.inf, plane_points, plane_tree)
        for i in range(n_close):
            lower[i] = plane_distance(kept_world, i, plane_points, plane_normals, first[i])
    floor, element = floor[close], element[close]
    bound = floor - lower  # the samples' violations are at most this
    violation, normals = np.empty(n_close), np.empty((n_close, 3))
    exact = np.zeros(n_close, np.bool_)
    # first the samples most likely to be kept (by their bound), then those still in doubt
    for most_likely in (True, False):
        candidates = np.flatnonzero(~exact)
        done = np.flatnonzero(exact)
        todo = undecided(bound[candidates], element[candidates],
                         np.concatenate((violation[done], known_violation)),
                         np.concatenate((element[done], known_element)), n_elements, activation,
                         max_rows, slack)
        candidates = candidates[todo]
        if most_likely:
            candidates = candidates[deepest_rows(bound[candidates], element[candidates], n_elements,
                                                 np.inf, max_rows)]
            candidates = candidates[np.argsort(candidates)]  # one sort compiled, as for the convex elements
        height, plane, _, _ = plane_estimates(kept_world[candidates], plane_points, plane_normals,
                                        plane_tree, k)
        for j in range(len(candidates)):
            c = candidates[j]
            violation[c] = floor[c] - height[j]
            copy_into(normals[c], plane_normals[plane[j]])
            exact[c] = True
    keep = np.flatnonzero(exact)
    return close[keep], normals[keep], violation[keep], nearest
