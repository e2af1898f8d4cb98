"""Where the time of an ISF round goes, in the lockstep engine.

A round (``isf.fitting.engine_kernel.run``) is one ISF iteration of every running fit in three
steps: *match* (each contact point's nearest object point, searched from its last answer by a
walk on the object's Delaunay graph, ``isf.search._neighbour_graph``; the outlier, normal and
duplicate filters; the pairs' moments), *IPFO* (palm and finger steps on the moments) and
*finish* (new contact points, the stop rule). This script runs the engine's rounds itself, step
by step, on the fits of ``bench_iteration.py`` (32 uniform-sampler starts, seed 0, on the paper
gripper and the ~2000-point bunny) and reports per fit-iteration: the time of each step, per
pyramid level how often a contact point's last answer is still its nearest point, and what the
walks save, measured in the same run as the extra time of the same rounds with every last
answer forgotten before each round (every query then searches the k-d tree from its root; the
answers, hence the rounds, are the same either way). Last, the match's searches alone: every
query of the rounds (its contact point and the object point its walk starts from) answered in
one compiled loop by ``isf.search.nearest.nearest_point``, a leaf kernel
(``isf.compiled.leaf``: compiled without numba's reference counting, inlined by LLVM), and by
the same function compiled as an ordinary kernel inlined by numba, with the ratio measured in
the same run and a check that both give the same answers.

Run from the repository root:  python bench/bench_rounds.py [--quick] [--repeats 5]
"""

from __future__ import annotations

import _common

import statistics
import time

import numpy as np
from numba import njit

import isf
from bench_iteration import GRIPPER, MAX_POINTS, starts
from isf.fitting import engine_kernel as kernel
from isf.fitting._ipfo import answer_requests
from isf.fitting._ipfo_kernel import DONE, alternate, no_answer
from isf.fitting.engine import LockstepFitter
from isf.search.nearest import nearest_point, search_scratch

FITS = 32

counted_nearest_point = njit(nogil=True, error_model="numpy", inline="always")(
    nearest_point.py_func)
"""``nearest_point`` compiled as an ordinary kernel inlined by numba, reference counting and all."""


@njit(cache=True)
def _unchanged(slots, grip, obj, hits, queries):
    """Add, per pyramid level, the running fits' contact points whose last answer is still their
    nearest object point (``hits``) and all of them (``queries``), at the state before a round."""
    status, level_of, current, last = slots.status, slots.level, slots.current, slots.last
    scratch = search_scratch()
    for b in range(len(status)):
        if status[b] != kernel.RUNNING:
            continue
        level = level_of[b]
        rows, count = grip.level_rows[level], grip.level_count[level]
        for i in range(count):
            g = rows[i]
            found, _ = nearest_point(current[b, i, 0], current[b, i, 1], current[b, i, 2], -1,
                                     obj.points, obj.tree, scratch, np.inf)
            hits[level] += found == last[b, g]
            queries[level] += 1


@njit(cache=True)
def _record_queries(slots, grip, queries, starts, n):
    """Append the running fits' contact points at the state before a round (``queries``) with
    the object point each one's search starts from (``starts``: its last answer, -1 for none)
    from row ``n``; returns the new count."""
    status, level_of, current, last = slots.status, slots.level, slots.current, slots.last
    for b in range(len(status)):
        if status[b] != kernel.RUNNING:
            continue
        rows, count = grip.level_rows[level_of[b]], grip.level_count[level_of[b]]
        for i in range(count):
            if n == len(starts):
                return n
            queries[n] = current[b, i]
            starts[n] = last[b, rows[i]]
            n += 1
    return n


@njit(cache=True)
def _leaf_searches(queries, starts, points, tree):
    """``nearest_point`` of each query from its start, in one loop: the answers."""
    scratch, found = search_scratch(), np.empty(len(starts), np.int64)
    for q in range(len(starts)):
        found[q], _ = nearest_point(queries[q, 0], queries[q, 1], queries[q, 2], starts[q],
                                    points, tree, scratch, np.inf)
    return found


@njit
def _counted_searches(queries, starts, points, tree):
    """:func:`_leaf_searches` with ``counted_nearest_point``."""
    scratch, found = search_scratch(), np.empty(len(starts), np.int64)
    for q in range(len(starts)):
        found[q], _ = counted_nearest_point(queries[q, 0], queries[q, 1], queries[q, 2],
                                            starts[q], points, tree, scratch, np.inf)
    return found


def round_queries(gripper, obj, proposals) -> tuple[np.ndarray, np.ndarray]:
    """Every search of the match in the rounds of all fits: contact points (Q, 3) and the object
    points their searches start from (Q,) (the previous point's answer is not tried here)."""
    fitter = LockstepFitter(gripper, obj)
    for i, p in enumerate(proposals):
        fitter.add(i, p.T_object_gripper, p.q)
    queries, starts, n = np.empty((1 << 20, 3)), np.empty(1 << 20, np.int64), 0
    while fitter.n_active:
        n = _record_queries(fitter._slots, fitter._grip, queries, starts, n)
        fitter.step()
    return queries[:n], starts[:n]


def time_searches(obj, queries, starts, repeats: int) -> dict:
    """Median ns per search of the leaf and the ordinary kernel, alternating, and whether their
    answers agree."""
    points, tree = obj.points, obj.search.tree
    same = np.array_equal(_leaf_searches(queries, starts, points, tree),
                          _counted_searches(queries, starts, points, tree))
    leaf, counted = [], []
    for _ in range(repeats):
        for loop, times in ((_leaf_searches, leaf), (_counted_searches, counted)):
            t0 = time.perf_counter()
            loop(queries, starts, points, tree)
            times.append((time.perf_counter() - t0) / len(starts) * 1e9)
    return {"leaf": statistics.median(leaf), "counted": statistics.median(counted), "same": same}


def run_rounds(gripper, obj, proposals, forget: bool, count_hits: bool) -> dict:
    """All fits to the end, round by round: seconds per step, fit-iterations, and the counts of
    last answers still nearest; ``forget``: every last answer dropped before each round."""
    fitter = LockstepFitter(gripper, obj)
    for i, p in enumerate(proposals):
        fitter.add(i, p.T_object_gripper, p.q)
    slots, history, grip = fitter._slots, fitter._history, fitter._grip
    fit_params, ipfo_params = fitter._fit_params, fitter._ipfo_params
    work = kernel._work(len(grip.point_link), len(obj.points))
    levels = fitter.config.levels
    hits, queries = np.zeros(levels, np.int64), np.zeros(levels, np.int64)
    seconds = np.zeros(3)
    fit_iterations = 0
    while np.any(slots.status == kernel.RUNNING):
        if count_hits:
            _unchanged(slots, grip, fitter._obj, hits, queries)
        if forget:
            slots.last[:] = -1
        t0 = time.perf_counter()
        pairs, state, moments = kernel._prepare(slots, grip, fitter._obj, fit_params, ipfo_params,
                                                work)
        t1 = time.perf_counter()
        if len(pairs.fits):
            request = alternate(state, moments, ipfo_params, 0, no_answer(state))
            if request.status != DONE:
                qps = [fitter._qp(b) for b in pairs.fits.tolist()] if gripper.n_joints else None
                answer_requests(gripper, qps, state, moments, ipfo_params, request)
        t2 = time.perf_counter()
        if len(pairs.fits):
            kernel.finish_round(slots, history, grip, fit_params, pairs, state)
        t3 = time.perf_counter()
        seconds += (t1 - t0, t2 - t1, t3 - t2)
        fit_iterations += len(pairs.fits)
        ended = slots.status > kernel.RUNNING
        slots.status[ended] = kernel.EMPTY  # ended fits leave, as in the engine
    return {"seconds": seconds, "fit_iterations": fit_iterations, "hits": hits, "queries": queries}


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=0)
    args = parser.parse_args()
    if args.quick:
        args.repeats = min(args.repeats, 2)
    started = time.perf_counter()
    header = _common.machine_description()
    gripper = isf.load_gripper(GRIPPER)
    if args.quick:
        obj = isf.open_object("shape:cylinder", max_points=MAX_POINTS)
    else:
        obj, _ = _common.scaled_benchmark_object("bunny", max_points=MAX_POINTS)
    proposals = starts(gripper, obj, FITS)
    counted = run_rounds(gripper, obj, proposals, forget=False, count_hits=True)
    run_rounds(gripper, obj, proposals, forget=True, count_hits=False)  # warm-up
    kept, forgotten = [], []
    for _ in range(args.repeats):  # interleaved, so both see the same machine
        kept.append(run_rounds(gripper, obj, proposals, forget=False, count_hits=False))
        forgotten.append(run_rounds(gripper, obj, proposals, forget=True, count_hits=False))
    n = counted["fit_iterations"]
    step = [statistics.median(r["seconds"][k] for r in kept) / n * 1e6 for k in range(3)]
    match_tree = statistics.median(r["seconds"][0] for r in forgotten) / n * 1e6
    hits, queries = counted["hits"], counted["queries"]
    saved_ns = (match_tree - step[0]) * n / max(int(queries.sum()), 1) * 1e3
    table = _common.markdown_table(
        ["object", "points", "fit-iterations", "match (us)", "IPFO (us)", "finish (us)",
         "round (us)", "match, every query from the tree's root (us)",
         "queries per fit-iteration", "saved per query by the walk (ns)"],
        [[obj.name, obj.n_points, n, _common.fmt(step[0]), _common.fmt(step[1]),
          _common.fmt(step[2]), _common.fmt(sum(step)), _common.fmt(match_tree),
          _common.fmt(queries.sum() / n), _common.fmt(saved_ns)]])
    search_points, query_starts = round_queries(gripper, obj, proposals)
    searches = time_searches(obj, search_points, query_starts, args.repeats)
    search_table = _common.markdown_table(
        ["searches", "from a last answer", "leaf kernel (ns per search)",
         "ordinary kernel (ns per search)", "ordinary / leaf", "same answers"],
        [[len(query_starts), f"{np.mean(query_starts >= 0):.1%}", _common.fmt(searches["leaf"]),
          _common.fmt(searches["counted"]), _common.fmt(searches["counted"] / searches["leaf"]),
          "yes" if searches["same"] else "NO"]])
    level_table = _common.markdown_table(
        ["pyramid level", "contact points matched", "last answer still the nearest"],
        [[level, int(queries[level]), f"{hits[level] / max(queries[level], 1):.1%}"]
         for level in range(len(queries))])
    note = (f"Gripper `{GRIPPER}`, {FITS} fits from uniform-sampler starts (seed 0) run to the end "
            f"in one lockstep batch; medians of {args.repeats} runs, per fit-iteration (wall "
            "time). Saved per query: (match from the tree's root - match) / the queries.")
    _common.finish("bench_rounds: where an ISF round's time goes",
                   ["### Steps of a round", note, table,
                    "### Searches from the last answer", level_table,
                    "### The match's searches: leaf kernel against ordinary kernel",
                    "Every search of the rounds above, from its contact point's last answer, "
                    f"in one compiled loop; medians of {args.repeats} alternating runs.",
                    search_table], started, header, args.out)


if __name__ == "__main__":
    main()
