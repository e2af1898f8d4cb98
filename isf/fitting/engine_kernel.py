"""The rounds of the lockstep engine, compiled: ISF iterations of many fits without Python.

:class:`isf.fitting.engine.LockstepFitter` keeps every fit's state in arrays, one *slot* per fit
(:func:`run` documents the tuples); :func:`run` advances all running slots round after round
(a round is one ISF iteration of each: correspondences, IPFO, the stop rule of Algorithm 2)
until one of them finishes, so Python sees a fit only when it starts and when it ends. One
round, for each running fit:

1. its level's contact points at its pose (kept from the previous round), matched to their
   nearest object points (below), filtered (outliers per
   contact surface or per fit, normal compatibility, duplicate targets), exactly as
   :func:`isf.fitting.correspondence.match_many` filters;
2. IPFO on the moments of the pairs (:func:`isf.fitting._ipfo_kernel.alternate`, all fits together);
   when it needs what only Python can do (an OSQP finger step, Pinocchio kinematics) the
   round pauses and :func:`run` returns the round's data for Python to finish the IPFO and
   call :func:`finish_round`;
3. the new pose's level points, the displacement ratio ``eta``, the history record, and the
   stop rule (next level, or the end of the fit).

Nearest points
--------------
Each fit keeps, per contact point, the object point found nearest in its last match. The next
match searches from there, or from the answer just found for the contact point before it when
that one is nearer (after a large step of the palm, neighbouring contact points have moved
alike) (:func:`isf.search.nearest.nearest_point`): on the object's Delaunay graph
(:mod:`isf.search._neighbour_graph`) a walk of a step or two, since an ISF iteration moves a contact
point by about one object point spacing or less; without a graph the k-d tree, bounded by
that point's distance. The answers are those of :class:`isf.search.nearest.NearestPoints`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .correspondence import keep_inliers, reject_duplicate_targets
from ._ipfo_kernel import DONE, resume
from ..search.kdtree import squared_distance
from .moment_kernels import fit_errors, group_moments, link_poses, place, points_in_object
from ..search.nearest import nearest_point, search_scratch

__all__ = ["CONVERGED", "EMPTY", "FINISHED", "IDLE", "LOST_CONTACT", "MAX_ITERATIONS",
           "PENDING", "ROUNDS", "RUNNING", "enter_level", "finish_round", "plane_distance", "run",
           "score_state"]

EMPTY, RUNNING, CONVERGED, MAX_ITERATIONS, LOST_CONTACT = -1, 0, 1, 2, 3
"""Slot states (a free slot, a running fit, and the three ways a fit ends)."""

IDLE, FINISHED, PENDING, ROUNDS = 0, 1, 2, 3
"""Why :func:`run` returned (no running fit, a fit finished, IPFO needs Python, the round limit)."""

@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def row_dot(a, i, b, j):
    """``a[i] . b[j]`` of two (., 3) arrays, summed in coordinate order."""
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def plane_distance(points, i, targets, normals, j):
    """``(points[i] - targets[j]) . normals[j]``: a point's signed distance from a tangent plane."""
    return ((points[i, 0] - targets[j, 0]) * normals[j, 0]
            + (points[i, 1] - targets[j, 1]) * normals[j, 1]
            + (points[i, 2] - targets[j, 2]) * normals[j, 2])


@njit(cache=True, nogil=True, error_model="numpy")
def _match(points, normals, rows, count, grip, obj, fit_params, last, dist, target, keep, work):
    """Match and filter the contact points ``rows[:count]`` (gripper point indices) at object-frame
    ``points``, ``normals`` (>= count, 3), each searched from its ``last`` answer (P,; -1: none,
    updated): fills ``dist``, ``target``, ``keep`` (>= count) and returns the number kept.
    ``work``: scratch from ``_work``."""
    point_surface = grip[3]
    obj_points, obj_normals, tree = obj
    per_surface, reject_duplicates, check_normals, cos_limit = fit_params[5:9]
    scratch, ranked, best_row, stamp, compatible = work
    for i in range(count):
        g = rows[i]
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        start = last[g]
        if i > 0 and start >= 0:  # or the previous point's answer, when nearer
            previous = target[i - 1]
            if (squared_distance(obj_points, previous, x, y, z)
                    < squared_distance(obj_points, start, x, y, z)):
                start = previous
        target[i], d2 = nearest_point(x, y, z, start, obj_points, tree, scratch, np.inf)
        last[g] = target[i]
        dist[i] = np.sqrt(d2)
        if check_normals:
            compatible[i] = row_dot(normals, i, obj_normals, target[i]) <= cos_limit
        else:
            compatible[i] = True
    a = 0
    while a < count:  # outlier groups: runs of one contact surface, or the whole fit
        b = a + 1
        if per_surface:
            while b < count and point_surface[rows[b]] == point_surface[rows[a]]:
                b += 1
        else:
            b = count
        keep_inliers(dist, a, b, fit_params[3], fit_params[4], compatible, keep, ranked)
        a = b
    if reject_duplicates:
        stamp[-1] += 1  # a fresh tag (the last entry counts calls; no object point uses it)
        reject_duplicate_targets(dist, target, 0, count, keep, best_row, stamp, stamp[-1])
    kept = 0
    for i in range(count):
        kept += keep[i]
    return kept


@njit(cache=True, nogil=True)
def _work(n_points, n_object):
    """Scratch of ``_match`` for up to ``n_points`` contact points: the tree's stack, a sort
    buffer, the duplicate filter's per-object-point arrays (``stamp`` with one extra entry that
    counts tags) and a compatibility mask."""
    stamp = np.full(n_object + 1, -1, np.int64)
    stamp[-1] = 0
    return (search_scratch(),
            np.empty(n_points), np.empty(n_object, np.int64), stamp, np.empty(n_points, np.bool_))


@njit(cache=True, nogil=True, error_model="numpy")
def _place_points(T, R, p, rows, count, grip, points, normals):
    """Object-frame positions and normals of gripper points ``rows[:count]`` of a fit at palm
    pose ``T`` (4, 4) and contact-link poses ``R`` (L, 3, 3), ``p`` (L, 3), into ``points``,
    ``normals`` (>= count, 3) (the arithmetic of :func:`isf.fitting.moment_kernels.points_in_object`)."""
    points_link, normals_link, point_link = grip[0], grip[1], grip[2]
    A, a = np.empty((len(R), 3, 3)), np.empty((len(R), 3))
    link_poses(T, R, p, A, a)
    for i in range(count):
        g = rows[i]
        place(A, a, point_link[g], points_link, normals_link, g, points, normals, i)


@njit(cache=True, nogil=True, error_model="numpy")
def enter_level(b, level, slots, grip, fit_params):
    """Start pyramid level ``level`` for slot ``b``: its contact points at the slot's state, the
    level's start positions, and a fresh stop rule."""
    T, R, p = slots[0], slots[2], slots[3]
    level_of, iteration, displacement, eta = slots[7], slots[8], slots[9], slots[10]
    current, current_normals, start = slots[11], slots[12], slots[13]
    rows, count = grip[4][level], grip[5][level]
    level_of[b], iteration[b], displacement[b], eta[b] = level, 0, np.inf, 0.0
    _place_points(T[b], R[b], p[b], rows, count, grip, current[b], current_normals[b])
    start[b, :count] = current[b, :count]


@njit(cache=True, nogil=True, error_model="numpy")
def _empty_round(n, n_links, n_ipfo):
    """A round's data with no fits (see :func:`run`), of the types a real round has."""
    return ((np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)),
             np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64)),
            (np.zeros((0, 4, 4)), np.zeros((0, n)), np.zeros((0, n_links, 3, 3)),
             np.zeros((0, n_links, 3)), np.zeros((0, n_links, 3, n)), np.zeros((0, n_links, 3, n)),
             np.zeros(0), np.zeros(0, np.bool_),
             np.zeros((0, n_ipfo)), np.zeros(0, np.int64)),
            (np.zeros((0, 3)), np.zeros(0), np.zeros((0, 12, 12)), np.zeros((0, 9, 9)),
             np.zeros((0, 12)),
             np.zeros(0), np.zeros((0, 9)), np.zeros((0, 4)), np.zeros(0), np.zeros(0)))


@njit(cache=True, nogil=True, error_model="numpy")
def _prepare(slots, grip, obj, fit_params, ipfo_params, work, n_links):
    """Step 1 of a round for every running slot (see the module docstring): the round's data.

    Returns ``(pairs, state, moments)``: ``pairs`` = (slot of each fit (F,), fit of each pair
    (K,), link (K,), link-frame points and normals (K, 3), targets and their normals (K, 3),
    pairs per fit (F,)); ``state`` = copies of the F fits' ``T, q, R, p, Jv, Jw``, their error E,
    IPFO's ``active`` flags, error log and log length; ``moments`` = the moments of
    :func:`isf.fitting.moment_kernels.group_moments` and IPFO's stop thresholds (F,). A slot left with
    fewer than ``min_pairs`` pairs ends as LOST_CONTACT."""
    T, q, R, p, Jv, Jw, status, level_of = slots[:8]
    current, current_normals = slots[11:13]
    last = slots[14]
    points_link, normals_link, point_link = grip[0], grip[1], grip[2]
    obj_points, obj_normals = obj[0], obj[1]
    n_points = len(point_link)
    n_slots = len(status)
    dist, target = np.empty(n_points), np.empty(n_points, np.int64)
    keep = np.empty(n_points, np.bool_)
    fits = np.empty(n_slots, np.int64)
    kept_rows = np.empty((n_slots, n_points), np.int64)
    kept_targets = np.empty((n_slots, n_points), np.int64)
    n_pairs = np.zeros(n_slots, np.int64)
    n_fits = 0
    for b in range(n_slots):
        if status[b] != RUNNING:
            continue
        rows, count = grip[4][level_of[b]], grip[5][level_of[b]]
        kept = _match(current[b], current_normals[b], rows, count, grip, obj, fit_params, last[b],
                      dist, target, keep, work)
        if kept < fit_params[9]:
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
    moments = group_moments(pair_fit, pair_link, pair_points, pair_normals, targets, target_normals,
                            n_fits, n_links)
    origin, fit_count, M, N, v, beta2, w, s, count_g = moments
    Tc, qc = np.empty((n_fits, 4, 4)), np.empty((n_fits, q.shape[1]))
    Rc, pc = np.empty((n_fits, n_links, 3, 3)), np.empty((n_fits, n_links, 3))
    n = q.shape[1]
    Jvc, Jwc = np.empty((n_fits, n_links, 3, n)), np.empty((n_fits, n_links, 3, n))
    for f in range(n_fits):
        b = fits[f]
        Tc[f], qc[f], Rc[f], pc[f], Jvc[f], Jwc[f] = T[b], q[b], R[b], p[b], Jv[b], Jw[b]
    error = fit_errors(Tc, Rc, pc, origin, M, N, v, beta2, w, count_g, ipfo_params[0] ** 2)
    threshold = ipfo_params[2] * n_pairs.astype(np.float64)
    log = np.empty((n_fits, ipfo_params[3]))
    active, n_log = np.ones(n_fits, np.bool_), np.zeros(n_fits, np.int64)
    state = (Tc, qc, Rc, pc, Jvc, Jwc, error, active, log, n_log)
    pairs = (fits, pair_fit, pair_link, pair_points, pair_normals, targets, target_normals, n_pairs)
    return pairs, state, (origin, fit_count, M, N, v, beta2, w, s, count_g, threshold)


@njit(cache=True, nogil=True, error_model="numpy")
def finish_round(slots, history, grip, fit_params, pairs, state):
    """Step 3 of a round (see the module docstring), after IPFO has run on ``state``: the fits'
    new states, history records, stop rules and level changes. Returns how many fits ended."""
    T, q, R, p, Jv, Jw, status, level_of, iteration, displacement, eta = slots[:11]
    current, current_normals, start = slots[11:14]
    h_level, h_iteration, h_distance, h_error, h_pairs, h_q, h_ipfo, h_n_ipfo, h_count = history
    fits, pair_fit, pair_link, pair_points, pair_normals, targets, target_normals, n_pairs = pairs
    Tc, qc, Rc, pc, Jvc, Jwc, error, _, log, n_log = state
    points, _ = points_in_object(Tc, Rc, pc, pair_fit, pair_link, pair_points, pair_normals)
    distance = np.zeros(len(fits))
    for k in range(len(pair_fit)):
        distance[pair_fit[k]] += abs(plane_distance(points, k, targets, target_normals, k))
    max_iterations, tolerance = fit_params[1], fit_params[2]
    ended = 0
    for f in range(len(fits)):
        b = fits[f]
        T[b], q[b], R[b], p[b], Jv[b], Jw[b] = Tc[f], qc[f], Rc[f], pc[f], Jvc[f], Jwc[f]
        level = level_of[b]
        rows, count = grip[4][level], grip[5][level]
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
        h_q[b, h] = q[b]
        h_ipfo[b, h], h_n_ipfo[b, h] = log[f], n_log[f]
        h_count[b] = h + 1
        eps = 2.0 ** level * tolerance
        converged = 1.0 - eps <= eta[b] <= 1.0 + eps
        if converged or iteration[b] >= max(1, max_iterations // 2 ** level):
            if level == 0:
                status[b] = CONVERGED if converged else MAX_ITERATIONS
                ended += 1
            else:
                enter_level(b, level - 1, slots, grip, fit_params)
    return ended


@njit(cache=True, nogil=True, error_model="numpy")
def run(slots, history, grip, obj, fit_params, ipfo_params, max_rounds):
    """Rounds of every running slot until one ends, IPFO needs Python, or ``max_rounds`` passed.

    Args:
        slots: per slot (S slots, P gripper points): ``T`` (S, 4, 4),
            ``q`` (S, n), contact-link ``R`` (S, L, 3, 3), ``p`` (S, L, 3), ``Jv``, ``Jw``
            (S, L, 3, n), ``status`` (S,), ``level``, ``iteration`` (S,), ``displacement``,
            ``eta`` (S,), the level's ``current`` points and normals and ``start`` points
            (S, P, 3), and each point's ``last`` nearest object point (S, P; -1: none).
            Updated in place.
        history: per slot and ISF iteration (H at most): level, iteration (S, H), mean
            distance, error (S, H), pairs (S, H), ``q`` (S, H, n), IPFO errors (S, H, I) and
            their count (S, H), and each slot's record count (S,).
        grip: the gripper's contact points and normals in their link frames (P, 3), link and
            surface of each point (P,), and the points of each pyramid level (levels, P) with
            their counts (levels,).
        obj: the object's points and normals (N, 3) and :attr:`isf.search.nearest.NearestPoints.tree`.
        fit_params: ``(levels, I0, eps0, outlier_factor, outlier_floor, per_surface,
            reject_duplicates, check_normals, -cos(max_normal_angle), min_pairs,
            contact_distance)`` (:class:`isf.config.FitConfig`).
        ipfo_params: :func:`isf.fitting._ipfo.ipfo_parameters`.
        max_rounds: rounds at most.

    Returns:
        ``(reason, rounds, pairs, state, moments, reply)``: why it returned (IDLE, FINISHED,
        PENDING or ROUNDS), the rounds completed, and for PENDING the paused round (as
        ``_prepare`` returns it) with IPFO's request ``reply``.
    """
    n_links, n, n_ipfo = slots[2].shape[1], slots[1].shape[1], ipfo_params[3]
    work = _work(len(grip[2]), len(obj[0]))
    pairs, state, moments = _empty_round(n, n_links, n_ipfo)
    reply = (DONE, 0, np.zeros((0, n, n)), np.zeros((0, n)), np.zeros((0, n)), np.zeros((0, n)),
             np.zeros((0, n)), np.zeros(0, np.bool_), np.zeros((0, n)), np.zeros(0, np.bool_))
    status = slots[6]
    for r in range(max_rounds):
        running = False
        for b in range(len(status)):
            running = running or status[b] == RUNNING
        if not running:
            return IDLE, r, pairs, state, moments, reply
        pairs, state, moments = _prepare(slots, grip, obj, fit_params, ipfo_params, work, n_links)
        ended = 0
        if len(pairs[0]):
            reply = resume(state, moments, ipfo_params, 0, False, np.zeros(state[1].shape), False,
                           state[2], state[3], state[4], state[5])
            if reply[0] != DONE:
                return PENDING, r, pairs, state, moments, reply
            ended = finish_round(slots, history, grip, fit_params, pairs, state)
        for b in range(len(status)):
            ended += status[b] > RUNNING
        if ended:
            return FINISHED, r + 1, pairs, state, moments, reply
    return ROUNDS, max_rounds, pairs, state, moments, reply


@njit(cache=True, nogil=True, error_model="numpy")
def score_state(T, R, p, grip, obj, fit_params, alpha, last):
    """The final scores of a fit at palm pose ``T`` (4, 4) and contact-link poses ``R``
    (L, 3, 3), ``p`` (L, 3): every contact point matched afresh (searched from its ``last``
    nearest object point, (P,), -1: none) and filtered.

    Returns:
        ``(mean_distance, misalignment, error, rows, targets, points, touching)``: the mean
        absolute point-to-plane distance (m), mean normal misalignment (rad) and E (m^2) of
        the kept pairs (inf when none), their gripper point indices and object point indices
        (K,), every contact point in the object frame (P, 3) and which lie within
        ``contact_distance`` of the object (P,).
    """
    n_points = len(grip[2])
    rows = np.arange(n_points)
    points, normals = np.empty((n_points, 3)), np.empty((n_points, 3))
    _place_points(T, R, p, rows, n_points, grip, points, normals)
    dist, target = np.empty(n_points), np.empty(n_points, np.int64)
    keep = np.empty(n_points, np.bool_)
    work = _work(n_points, len(obj[0]))
    kept = _match(points, normals, rows, n_points, grip, obj, fit_params, last, dist, target, keep,
                  work)
    obj_points, obj_normals = obj[0], obj[1]
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
    touching = dist <= fit_params[10]
    if kept == 0:
        return np.inf, np.inf, np.inf, kept_rows, kept_targets, points, touching
    return distance / kept, misalignment / kept, error, kept_rows, kept_targets, points, touching
