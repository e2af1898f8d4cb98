"""The rounds of the lockstep engine, compiled: ISF iterations of many fits without Python.

:class:`isf.fitting.engine.LockstepFitter` keeps every fit's state in arrays, one *slot* per fit
(:class:`Slots`, :class:`HistoryArrays`); :func:`run` advances all running slots round after
round (a round is one ISF iteration of each: correspondences, IPFO, the stop rule of
Algorithm 2) until one of them finishes, so Python sees a fit only when it starts and when it
ends. One round, for each running fit:

1. its level's contact points at its pose (kept from the previous round), matched to their
   nearest object points (below), filtered (outliers per contact surface or per fit, normal
   compatibility, duplicate targets), exactly as :func:`isf.fitting.correspondence.match_many`
   filters;
2. IPFO on the moments of the pairs (:func:`isf.fitting._ipfo_kernel.alternate`, all fits
   together); when it needs what only Python can do (an OSQP finger step, Pinocchio kinematics) the
   round pauses and :func:`run` returns the round's data for Python to finish the IPFO and
   call :func:`finish_round`;
3. the new pose's level points, the displacement ratio ``eta``, the history record, and the
   stop rule (next level, or the end of the fit).

A fit's first round also records its iteration 0 (:func:`record_start`): the start pose with the
pairs matched there, before IPFO moves it.

Nearest points
--------------
Each fit keeps, per contact point, the object point found nearest in its last match. The next
match searches from there, or from the answer just found for the contact point before it when
that one is nearer (after a large step of the palm, neighbouring contact points have moved
alike) (:func:`isf.search.nearest.nearest_point`): on the object's Delaunay graph
(:mod:`isf.search._neighbour_graph`) a walk of a step or two, since an ISF iteration moves a contact
point by about one object point spacing or less; without a graph the k-d tree, bounded by
that point's distance. The answers are those of :class:`isf.search.nearest.NearestPoints`.

Literal constants
-----------------
numba types an integer constant passed to a compiled callee as a literal (``Literal[int](0)``)
and compiles the callee once more for it, beside the ``int64`` version that Python callers
and loop variables use. The calls below that pass a start of 0 pass ``np.int64(0)`` instead:
one compiled version of each callee, the same machine arithmetic, a shorter first run.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.arrays import copy_into
from ..compiled.kernels import kernel
from ..search.kdtree import squared_distance
from ..search.nearest import nearest_point, search_scratch
from ._ipfo_kernel import DONE, IPFOMoments, IPFORequest, IPFOState, alternate, no_answer
from .correspondence import keep_inliers, reject_duplicate_targets
from .moment_kernels import (
    GroupMoments,
    fit_errors,
    group_moments,
    link_poses,
    place,
    points_in_object,
)

__all__ = ["CONVERGED", "EMPTY", "FINISHED", "IDLE", "LOST_CONTACT", "MAX_ITERATIONS",
           "PENDING", "ROUNDS", "RUNNING", "FitParameters", "GripperArrays", "HistoryArrays",
           "ObjectArrays", "Round", "RoundPairs", "Score", "Slots", "enter_level", "finish_round",
           "plane_distance", "record_start", "row_dot", "run", "score_state"]

EMPTY, RUNNING, CONVERGED, MAX_ITERATIONS, LOST_CONTACT = -1, 0, 1, 2, 3
"""Slot states (a free slot, a running fit, and the three ways a fit ends)."""

IDLE, FINISHED, PENDING, ROUNDS = 0, 1, 2, 3
"""Why :func:`run` returned (no running fit, a fit finished, IPFO needs Python, the round limit)."""


class Slots(NamedTuple):
    """Every fit's state, one slot per fit, updated in place (S slots, n joints, L contact
    links, P gripper contact points).

    Attributes:
        T: palm pose ``T_object_gripper``, (S, 4, 4) float64.
        q: joints, (S, n) float64 (rad or m).
        R: contact-link rotations ``R_gripper_link``, (S, L, 3, 3) float64.
        p: contact-link origins in the gripper frame, (S, L, 3) float64, m.
        Jv: Jacobians of the link origins, (S, L, 3, n) float64.
        Jw: angular Jacobians of the links, (S, L, 3, n) float64.
        status: EMPTY, RUNNING or how the fit ended, (S,) int64.
        level: pyramid level, (S,) int64.
        iteration: ISF iterations on the level, (S,) int64.
        displacement: ``e_s``, the level's contact points' displacement since the level began,
            (S,) float64, m.
        eta: ``e_s / e_s,prev``, (S,) float64.
        current: the level's contact points at the fit's pose, object frame, (S, P, 3) float64,
            m (the first ``level_count[level]`` rows count).
        current_normals: their normals, (S, P, 3) float64.
        start: the level's contact points when the level began, (S, P, 3) float64, m.
        last: each contact point's last nearest object point, (S, P) int64 (-1: none).
    """

    T: np.ndarray
    q: np.ndarray
    R: np.ndarray
    p: np.ndarray
    Jv: np.ndarray
    Jw: np.ndarray
    status: np.ndarray
    level: np.ndarray
    iteration: np.ndarray
    displacement: np.ndarray
    eta: np.ndarray
    current: np.ndarray
    current_normals: np.ndarray
    start: np.ndarray
    last: np.ndarray


class HistoryArrays(NamedTuple):
    """Every fit's record of its start (iteration 0) and of each ISF iteration, in place (S slots,
    H records at most, I IPFO alternations at most; :class:`isf.result.History` reads them).

    Attributes:
        level, iteration: pyramid level and iteration on it (0: the start), (S, H) int64.
        mean_distance: mean absolute point-to-plane distance of the pairs, (S, H) float64, m.
        error: E after IPFO (at the start: before it), (S, H) float64, m^2.
        n_pairs: pairs, (S, H) int64.
        q: joints after the iteration, (S, H, n) float64.
        ipfo_errors: IPFO's E after each kept alternation, (S, H, I) float64, m^2.
        n_ipfo: entries of each ``ipfo_errors`` row, (S, H) int64.
        count: records of each slot, (S,) int64.
        T: palm pose ``T_object_gripper`` after the iteration, (S, H, 4, 4) float64.
        eta: the stop rule's displacement ratio after the iteration (NaN at the start),
            (S, H) float64.
    """

    level: np.ndarray
    iteration: np.ndarray
    mean_distance: np.ndarray
    error: np.ndarray
    n_pairs: np.ndarray
    q: np.ndarray
    ipfo_errors: np.ndarray
    n_ipfo: np.ndarray
    count: np.ndarray
    T: np.ndarray
    eta: np.ndarray


class GripperArrays(NamedTuple):
    """The gripper's contact points (P points, ``levels`` pyramid levels).

    Attributes:
        points_link: each point in its link's frame, (P, 3) float64, m.
        normals_link: its outward normal in the link's frame, (P, 3) float64.
        point_link: its contact link, (P,) int64.
        point_surface: its contact surface, (P,) int64.
        level_rows: the points of each pyramid level, (levels, P) int64, padded.
        level_count: how many points each level has, (levels,) int64.
    """

    points_link: np.ndarray
    normals_link: np.ndarray
    point_link: np.ndarray
    point_surface: np.ndarray
    level_rows: np.ndarray
    level_count: np.ndarray


class ObjectArrays(NamedTuple):
    """The object surface (N points).

    Attributes:
        points: surface points, (N, 3) float64, m.
        normals: outward unit normals, (N, 3) float64.
        tree: :attr:`isf.search.nearest.NearestPoints.tree`, passed to
            :func:`isf.search.nearest.nearest_point` as it is.
    """

    points: np.ndarray
    normals: np.ndarray
    tree: object


class FitParameters(NamedTuple):
    """The constants of the engine from :class:`isf.config.FitConfig`
    (:func:`isf.fitting.engine.fit_parameters`).

    Attributes:
        levels: pyramid levels, int.
        max_iterations: ``I0``, ISF iterations of level 0 at most, int.
        tolerance: ``eps0`` of the stop rule, float.
        outlier_factor, outlier_floor: the outlier filter's factor and floor (m), float.
        per_surface: whether outliers are judged per contact surface (else per fit), bool.
        reject_duplicates: whether only the nearest of the points sharing a target stays, bool.
        check_normals: whether pairs with incompatible normals are dropped, bool.
        cos_limit: ``-cos(max_normal_angle)``: the largest normal dot product kept, float.
        min_pairs: pairs a fit needs to go on, int.
        contact_distance: the distance within which a contact point touches, float, m.
    """

    levels: int
    max_iterations: int
    tolerance: float
    outlier_factor: float
    outlier_floor: float
    per_surface: bool
    reject_duplicates: bool
    check_normals: bool
    cos_limit: float
    min_pairs: int
    contact_distance: float


class RoundPairs(NamedTuple):
    """The pairs of a round's F fits, back to back (K pairs).

    Attributes:
        fits: the slot of each fit, (F,) int64.
        pair_fit: the fit of each pair, (K,) int64.
        link: its contact link, (K,) int64.
        points_link, normals_link: its gripper point and normal in the link frame, (K, 3)
            float64 (m).
        targets, target_normals: its object point and normal, (K, 3) float64 (m).
        n_pairs: pairs of each fit, (F,) int64.
    """

    fits: np.ndarray
    pair_fit: np.ndarray
    link: np.ndarray
    points_link: np.ndarray
    normals_link: np.ndarray
    targets: np.ndarray
    target_normals: np.ndarray
    n_pairs: np.ndarray


class Round(NamedTuple):
    """What :func:`run` returns.

    Attributes:
        reason: why it returned: IDLE, FINISHED, PENDING or ROUNDS, int.
        rounds: the rounds completed, int.
        pairs: for PENDING, the paused round's :class:`RoundPairs`.
        state: its :class:`isf.fitting._ipfo_kernel.IPFOState`.
        moments: its :class:`isf.fitting._ipfo_kernel.IPFOMoments`.
        request: IPFO's :class:`isf.fitting._ipfo_kernel.IPFORequest`.
    """

    reason: int
    rounds: int
    pairs: RoundPairs
    state: IPFOState
    moments: IPFOMoments
    request: IPFORequest


class Score(NamedTuple):
    """What :func:`score_state` returns (P contact points, K kept pairs).

    Attributes:
        mean_distance: mean absolute point-to-plane distance of the pairs, float, m (inf: none).
        misalignment: their mean normal misalignment, float, rad (inf: none).
        error: their E, float, m^2 (inf: none).
        rows: their gripper point indices, (K,) int64.
        targets: their object point indices, (K,) int64.
        points: every contact point in the object frame, (P, 3) float64, m.
        touching: which contact points lie within ``contact_distance`` of the object, (P,) bool.
    """

    mean_distance: float
    misalignment: float
    error: float
    rows: np.ndarray
    targets: np.ndarray
    points: np.ndarray
    touching: np.ndarray


class _MatchScratch(NamedTuple):
    """Scratch of ``_match`` (P contact points, N object points).

    Attributes:
        search: :func:`isf.search.nearest.search_scratch`.
        ranked: a sort buffer, (P,) float64.
        best_row: the duplicate filter's row per object point, (N,) int64.
        stamp: the duplicate filter's tag per object point, (N + 1,) int64; the last entry
            counts the tags given.
        compatible: the normal test of each point, (P,) bool.
    """

    search: object
    ranked: np.ndarray
    best_row: np.ndarray
    stamp: np.ndarray
    compatible: np.ndarray

@kernel(inline=True)
def row_dot(a, i, b, j):
    """``a[i] . b[j]`` of two (., 3) arrays, summed in coordinate order."""
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@kernel(inline=True)
def plane_distance(points, i, targets, normals, j):
    """``(points[i] - targets[j]) . normals[j]``: a point's signed distance from a tangent plane."""
    return ((points[i, 0] - targets[j, 0]) * normals[j, 0]
            + (points[i, 1] - targets[j, 1]) * normals[j, 1]
            + (points[i, 2] - targets[j, 2]) * normals[j, 2])


@kernel
def _match(points, normals, rows, count, grip, obj, fit_params, last, dist, target, keep, work):
    """Match and filter the contact points ``rows[:count]`` (gripper point indices) at object-frame
    ``points``, ``normals`` (>= count, 3), each searched from its ``last`` answer (P,; -1: none,
    updated): fills ``dist``, ``target``, ``keep`` (>= count) and returns the number kept.
    ``grip``: :class:`GripperArrays`; ``obj``: :class:`ObjectArrays`; ``fit_params``:
    :class:`FitParameters`; ``work``: :class:`_MatchScratch` from ``_work``."""
    # fields read once, outside the loops (each read of an array field counts a reference)
    point_surface = grip.point_surface
    obj_points, obj_normals, tree = obj.points, obj.normals, obj.tree
    search, ranked, compatible = work.search, work.ranked, work.compatible
    check_normals, cos_limit = fit_params.check_normals, fit_params.cos_limit
    per_surface = fit_params.per_surface
    outlier_factor, outlier_floor = fit_params.outlier_factor, fit_params.outlier_floor
    for i in range(count):
        g = rows[i]
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        start = last[g]
        if i > 0 and start >= 0:  # or the previous point's answer, when nearer
            previous = target[i - 1]
            if (squared_distance(obj_points, previous, x, y, z)
                    < squared_distance(obj_points, start, x, y, z)):
                start = previous
        target[i], d2 = nearest_point(x, y, z, start, obj_points, tree, search, np.inf)
        last[g] = target[i]
        dist[i] = np.sqrt(d2)
        if check_normals:
            compatible[i] = row_dot(normals, i, obj_normals, target[i]) <= cos_limit
        else:
            compatible[i] = True
    a = np.int64(0)  # typed, not a literal 0: see the module docstring, "Literal constants"
    while a < count:  # outlier groups: runs of one contact surface, or the whole fit
        b = a + 1
        if per_surface:
            while b < count and point_surface[rows[b]] == point_surface[rows[a]]:
                b += 1
        else:
            b = count
        keep_inliers(dist, a, b, outlier_factor, outlier_floor, compatible, keep, ranked)
        a = b
    if fit_params.reject_duplicates:
        stamp = work.stamp
        stamp[-1] += 1  # a fresh tag (the last entry counts calls; no object point uses it)
        reject_duplicate_targets(dist, target, np.int64(0), count, keep, work.best_row, stamp, stamp[-1])
    kept = 0
    for i in range(count):
        kept += keep[i]
    return kept


@kernel(error_model="python")
def _work(n_points, n_object):
    """The :class:`_MatchScratch` of ``_match`` for up to ``n_points`` contact points and
    ``n_object`` object points."""
    stamp = np.full(n_object + 1, -1, np.int64)
    stamp[-1] = 0
    return _MatchScratch(search_scratch(), np.empty(n_points), np.empty(n_object, np.int64), stamp,
                         np.empty(n_points, np.bool_))


@kernel
def _place_points(T, R, p, rows, count, grip, points, normals):
    """Object-frame positions and normals of gripper points ``rows[:count]`` of a fit at palm
    pose ``T`` (4, 4) and contact-link poses ``R`` (L, 3, 3), ``p`` (L, 3), into ``points``,
    ``normals`` (>= count, 3) (the arithmetic of
    :func:`isf.fitting.moment_kernels.points_in_object`); ``grip``: :class:`GripperArrays`."""
    points_link, normals_link, point_link = grip.points_link, grip.normals_link, grip.point_link
    A, a = np.empty((len(R), 3, 3)), np.empty((len(R), 3))
    link_poses(T, R, p, A, a)
    for i in range(count):
        g = rows[i]
        place(A, a, point_link[g], points_link, normals_link, g, points, normals, i)


@kernel
def enter_level(b, level, slots, grip):
    """Start pyramid level ``level`` for slot ``b`` of ``slots`` (:class:`Slots`): its contact
    points at the slot's state, the level's start positions, and a fresh stop rule."""
    rows, count = grip.level_rows[level], grip.level_count[level]
    slots.level[b], slots.iteration[b] = level, 0
    slots.displacement[b], slots.eta[b] = np.inf, 0.0
    current = slots.current
    _place_points(slots.T[b], slots.R[b], slots.p[b], rows, count, grip, current[b],
                  slots.current_normals[b])
    copy_into(slots.start[b, :count], current[b, :count])


@kernel
def _empty_round(n, n_links, n_ipfo):
    """The pairs, IPFO state, moments and request of a round with no fits (see :func:`run`), of
    the types a real round has (n joints, L links, I IPFO alternations)."""
    no_ints, no_rows = np.zeros(0, np.int64), np.zeros((0, 3))
    pairs = RoundPairs(no_ints, no_ints, no_ints, no_rows, no_rows, no_rows, no_rows, no_ints)
    state = IPFOState(np.zeros((0, 4, 4)), np.zeros((0, n)), np.zeros((0, n_links, 3, 3)),
                      np.zeros((0, n_links, 3)), np.zeros((0, n_links, 3, n)),
                      np.zeros((0, n_links, 3, n)), np.zeros(0), np.zeros(0, np.bool_),
                      np.zeros((0, n_ipfo)), np.zeros(0, np.int64))
    moments = IPFOMoments(GroupMoments(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 12, 12)),
                                       np.zeros((0, 9, 9)), np.zeros((0, 12)), np.zeros(0),
                                       np.zeros((0, 9)), np.zeros((0, 4)), np.zeros(0)),
                          np.zeros(0))
    none = np.zeros((0, n))
    request = IPFORequest(DONE, 0, np.zeros((0, n, n)), none, none, none, none,
                          np.zeros(0, np.bool_), none, np.zeros(0, np.bool_))
    return pairs, state, moments, request


@kernel
def _prepare(slots, grip, obj, fit_params, ipfo_params, work):
    """Step 1 of a round for every running slot (see the module docstring): the round's data.

    Returns ``(pairs, state, moments)``: the round's :class:`RoundPairs`, copies of the F
    fits' state as an :class:`isf.fitting._ipfo_kernel.IPFOState` (E at the current state,
    every fit active, an empty log) and the pairs' moments with IPFO's stop thresholds
    (:class:`isf.fitting._ipfo_kernel.IPFOMoments`). A slot left with fewer than ``min_pairs``
    pairs ends as LOST_CONTACT."""
    T, q, R, p, Jv, Jw = slots.T, slots.q, slots.R, slots.p, slots.Jv, slots.Jw
    status, level_of, last = slots.status, slots.level, slots.last
    current, current_normals = slots.current, slots.current_normals
    points_link, normals_link, point_link = grip.points_link, grip.normals_link, grip.point_link
    obj_points, obj_normals = obj.points, obj.normals
    level_rows, level_count = grip.level_rows, grip.level_count
    n_links = R.shape[1]
    n_points = len(point_link)
    n_slots = len(status)
    dist, target = np.empty(n_points), np.empty(n_points, np.int64)
    keep = np.empty(n_points, np.bool_)
    fits = np.empty(n_slots, np.int64)
    kept_rows = np.empty((n_slots, n_points), np.int64)
    kept_targets = np.empty((n_slots, n_points), np.int64)
    n_pairs = np.zeros(n_slots, np.int64)
    n_fits = np.int64(0)  # typed, not a literal 0: see the module docstring, "Literal constants"
    for b in range(n_slots):
        if status[b] != RUNNING:
            continue
        rows, count = level_rows[level_of[b]], level_count[level_of[b]]
        kept = _match(current[b], current_normals[b], rows, count, grip, obj, fit_params, last[b],
                      dist, target, keep, work)
        if kept < fit_params.min_pairs:
            status[b] = LOST_CONTACT
            continue
        k = 0
        for i in range(count):
            if keep[i]:
                kept_rows[n_fits, k], kept_targets[n_fits, k] = rows[i], target[i]
                k += 1
        fits[n_fits], n_pairs[n_fits] = b, kept
        n_fits += 1
    fits, n_pairs = fits[:n_fits].copy(), n_pairs[:n_fits].copy()
    total = n_pairs.sum()
    pair_fit, pair_link = np.empty(total, np.int64), np.empty(total, np.int64)
    pair_points, pair_normals = np.empty((total, 3)), np.empty((total, 3))
    targets, target_normals = np.empty((total, 3)), np.empty((total, 3))
    k = 0
    for f in range(n_fits):
        for i in range(n_pairs[f]):
            g, t = kept_rows[f, i], kept_targets[f, i]
            pair_fit[k], pair_link[k] = f, point_link[g]
            for j in range(3):
                pair_points[k, j], pair_normals[k, j] = points_link[g, j], normals_link[g, j]
                targets[k, j], target_normals[k, j] = obj_points[t, j], obj_normals[t, j]
            k += 1
    sums = group_moments(pair_fit, pair_link, pair_points, pair_normals, targets, target_normals,
                         n_fits, n_links)
    n = q.shape[1]
    Tc, qc = np.empty((n_fits, 4, 4)), np.empty((n_fits, n))
    Rc, pc = np.empty((n_fits, n_links, 3, 3)), np.empty((n_fits, n_links, 3))
    Jvc, Jwc = np.empty((n_fits, n_links, 3, n)), np.empty((n_fits, n_links, 3, n))
    for f in range(n_fits):
        b = fits[f]
        copy_into(Tc[f], T[b]), copy_into(qc[f], q[b]), copy_into(Rc[f], R[b])
        copy_into(pc[f], p[b]), copy_into(Jvc[f], Jv[b]), copy_into(Jwc[f], Jw[b])
    alpha = ipfo_params.alpha
    error = fit_errors(Tc, Rc, pc, sums.origin, sums.M, sums.N, sums.v, sums.beta2, sums.w,
                       sums.count, alpha ** 2)
    threshold = ipfo_params.tolerance * n_pairs.astype(np.float64)
    log = np.empty((n_fits, ipfo_params.max_iterations))
    active, n_log = np.ones(n_fits, np.bool_), np.zeros(n_fits, np.int64)
    state = IPFOState(Tc, qc, Rc, pc, Jvc, Jwc, error, active, log, n_log)
    pairs = RoundPairs(fits, pair_fit, pair_link, pair_points, pair_normals, targets,
                       target_normals, n_pairs)
    moments = IPFOMoments(sums, threshold)
    return pairs, state, moments


@kernel
def finish_round(slots, history, grip, fit_params, pairs, state):
    """Step 3 of a round (see the module docstring), after IPFO has run on ``state``: the fits'
    new states, history records, stop rules and level changes. Arguments as :func:`run` takes
    them and the round's :class:`RoundPairs` and IPFO state. Returns how many fits ended."""
    T, q, R, p, Jv, Jw = slots.T, slots.q, slots.R, slots.p, slots.Jv, slots.Jw
    status, level_of, iteration = slots.status, slots.level, slots.iteration
    displacement, eta = slots.displacement, slots.eta
    current, current_normals, start = slots.current, slots.current_normals, slots.start
    fits, pair_fit, n_pairs = pairs.fits, pairs.pair_fit, pairs.n_pairs
    targets, target_normals = pairs.targets, pairs.target_normals
    Tc, qc, Rc, pc, Jvc, Jwc = state.T, state.q, state.R, state.p, state.Jv, state.Jw
    points, _ = points_in_object(Tc, Rc, pc, pair_fit, pairs.link, pairs.points_link,
                                 pairs.normals_link)
    distance = np.zeros(len(fits))
    for k in range(len(pair_fit)):
        distance[pair_fit[k]] += abs(plane_distance(points, k, targets, target_normals, k))
    max_iterations, tolerance = fit_params.max_iterations, fit_params.tolerance
    level_rows, level_count = grip.level_rows, grip.level_count
    error, log, n_log = state.error, state.log, state.n_log
    h_level, h_iteration, h_distance = history.level, history.iteration, history.mean_distance
    h_error, h_pairs, h_q = history.error, history.n_pairs, history.q
    h_ipfo, h_n_ipfo, h_count = history.ipfo_errors, history.n_ipfo, history.count
    h_T, h_eta = history.T, history.eta
    ended = 0
    for f in range(len(fits)):
        b = fits[f]
        copy_into(T[b], Tc[f]), copy_into(q[b], qc[f]), copy_into(R[b], Rc[f])
        copy_into(p[b], pc[f]), copy_into(Jv[b], Jvc[f]), copy_into(Jw[b], Jwc[f])
        level = level_of[b]
        rows, count = level_rows[level], level_count[level]
        _place_points(T[b], R[b], p[b], rows, count, grip, current[b], current_normals[b])
        iteration[b] += 1
        moved = np.empty(3 * count)
        for i in range(count):
            for j in range(3):
                moved[3 * i + j] = current[b, i, j] - start[b, i, j]
        previous = displacement[b]
        displacement[b] = np.sqrt(np.dot(moved, moved))  # BLAS, as numpy's moved @ moved
        eta[b] = 1.0 if displacement[b] <= 1e-12 else displacement[b] / previous
        h = h_count[b]
        h_level[b, h], h_iteration[b, h] = level, iteration[b]
        h_distance[b, h], h_error[b, h] = distance[f] / n_pairs[f], error[f]
        h_pairs[b, h] = n_pairs[f]
        copy_into(h_q[b, h], q[b]), copy_into(h_T[b, h], T[b])
        h_eta[b, h] = eta[b]
        copy_into(h_ipfo[b, h], log[f])
        h_n_ipfo[b, h] = n_log[f]
        h_count[b] = h + 1
        eps = 2.0 ** level * tolerance
        converged = 1.0 - eps <= eta[b] <= 1.0 + eps
        if converged or iteration[b] >= max(1, max_iterations // 2 ** level):
            if level == 0:
                status[b] = CONVERGED if converged else MAX_ITERATIONS
                ended += 1
            else:
                enter_level(b, level - 1, slots, grip)
    return ended


@kernel
def record_start(slots, history, pairs, state):
    """Iteration 0 of the round's fits that have no record yet: their start pose and joints,
    the pairs matched there, their mean distance and E, before IPFO (``pairs``: the round's
    :class:`RoundPairs`; ``state``: its IPFO state as ``_prepare`` returns it, not yet
    alternated)."""
    fits, pair_fit, n_pairs, count = pairs.fits, pairs.pair_fit, pairs.n_pairs, history.count
    starting = False
    for f in range(len(fits)):
        starting = starting or count[fits[f]] == 0
    if not starting:
        return
    points, _ = points_in_object(state.T, state.R, state.p, pair_fit, pairs.link,
                                 pairs.points_link, pairs.normals_link)
    targets, target_normals = pairs.targets, pairs.target_normals
    distance = np.zeros(len(fits))
    for k in range(len(pair_fit)):
        distance[pair_fit[k]] += abs(plane_distance(points, k, targets, target_normals, k))
    for f in range(len(fits)):
        b = fits[f]
        if count[b] != 0:
            continue
        history.level[b, 0], history.iteration[b, 0] = slots.level[b], 0
        history.mean_distance[b, 0] = distance[f] / n_pairs[f]
        history.error[b, 0], history.n_pairs[b, 0] = state.error[f], n_pairs[f]
        copy_into(history.q[b, 0], state.q[f]), copy_into(history.T[b, 0], state.T[f])
        history.eta[b, 0] = np.nan
        history.n_ipfo[b, 0] = 0
        count[b] = 1


@kernel
def run(slots, history, grip, obj, fit_params, ipfo_params, max_rounds):
    """Rounds of every running slot until one ends, IPFO needs Python, or ``max_rounds`` passed.

    Args:
        slots: :class:`Slots`, updated in place.
        history: :class:`HistoryArrays`, updated in place.
        grip: :class:`GripperArrays`.
        obj: :class:`ObjectArrays`.
        fit_params: :class:`FitParameters`.
        ipfo_params: :class:`isf.fitting._ipfo_kernel.IPFOParameters`.
        max_rounds: rounds at most.

    Returns:
        A :class:`Round`: why it returned, the rounds completed, and for PENDING the paused
        round (as ``_prepare`` returns it) with IPFO's request.
    """
    n_links, n, n_ipfo = slots.R.shape[1], slots.q.shape[1], ipfo_params.max_iterations
    work = _work(len(grip.point_link), len(obj.points))
    pairs, state, moments, request = _empty_round(n, n_links, n_ipfo)
    status = slots.status
    for r in range(max_rounds):
        running = False
        for b in range(len(status)):
            running = running or status[b] == RUNNING
        if not running:
            return Round(IDLE, r, pairs, state, moments, request)
        pairs, state, moments = _prepare(slots, grip, obj, fit_params, ipfo_params, work)
        record_start(slots, history, pairs, state)
        ended = 0
        if len(pairs.fits):
            request = alternate(state, moments, ipfo_params, np.int64(0), no_answer(state))
            if request.status != DONE:
                return Round(PENDING, r, pairs, state, moments, request)
            ended = finish_round(slots, history, grip, fit_params, pairs, state)
        for b in range(len(status)):
            ended += status[b] > RUNNING
        if ended:
            return Round(FINISHED, r + 1, pairs, state, moments, request)
    return Round(ROUNDS, max_rounds, pairs, state, moments, request)


@kernel
def score_state(T, R, p, grip, obj, fit_params, alpha, last):
    """The final :class:`Score` of a fit at palm pose ``T`` (4, 4) and contact-link poses ``R``
    (L, 3, 3), ``p`` (L, 3): every contact point matched afresh (searched from its ``last``
    nearest object point, (P,), -1: none) and filtered; ``alpha``: the weight of the normal
    term (m); the rest as :func:`run` takes them.
    """
    n_points = len(grip.point_link)
    rows = np.arange(n_points)
    points, normals = np.empty((n_points, 3)), np.empty((n_points, 3))
    _place_points(T, R, p, rows, n_points, grip, points, normals)
    dist, target = np.empty(n_points), np.empty(n_points, np.int64)
    keep = np.empty(n_points, np.bool_)
    work = _work(n_points, len(obj.points))
    kept = _match(points, normals, rows, n_points, grip, obj, fit_params, last, dist, target, keep,
                  work)
    obj_points, obj_normals = obj.points, obj.normals
    kept_rows, kept_targets = np.empty(kept, np.int64), np.empty(kept, np.int64)
    distance = misalignment = error = 0.0
    k = 0
    for i in range(n_points):
        if not keep[i]:
            continue
        t = target[i]
        d = plane_distance(points, i, obj_points, obj_normals, t)
        c = row_dot(normals, i, obj_normals, t) + 1.0
        distance += abs(d)
        misalignment += np.arccos(min(max(1.0 - c, -1.0), 1.0))
        error += d * d + alpha * alpha * (c * c)
        kept_rows[k], kept_targets[k] = i, t
        k += 1
    touching = dist <= fit_params.contact_distance
    if kept == 0:
        return Score(np.inf, np.inf, np.inf, kept_rows, kept_targets, points, touching)
    return Score(distance / kept, misalignment / kept, error, kept_rows, kept_targets, points,
                 touching)
