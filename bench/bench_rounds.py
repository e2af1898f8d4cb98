"""Where the time of an ISF round goes, in the lockstep engine.

A round (``isf.lockstep_kernel.run``) is one ISF iteration of every running fit in three steps:
*match* (each contact point's nearest object point, searched from its last answer by a walk on
the object's Delaunay graph, ``isf.neighbour_graph``; the outlier, normal and duplicate
filters; the pairs' moments), *IPFO* (palm and finger steps on the moments) and *finish* (new
contact points, the stop rule). This script runs the engine's rounds itself, step by step, on
the fits of ``bench_iteration.py`` (32 uniform-sampler starts, seed 0, on the paper gripper and
the ~2000-point bunny) and reports per fit-iteration: the time of each step, per pyramid level
how often a contact point's last answer is still its nearest point, and what the walks save,
measured in the same run as the extra time of the same rounds with every last answer
forgotten before each round (every query then searches the k-d tree from its root; the
answers, hence the rounds, are the same either way).

Run from the repository root:  python bench/bench_rounds.py [--quick] [--repeats 5]
"""

from __future__ import annotations

import _common  # noqa: I001  (first: pins BLAS/OpenMP threads before numpy is imported)

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

import isf  # noqa: E402
from bench_iteration import GRIPPER, MAX_POINTS, starts  # noqa: E402
from isf import lockstep_kernel as kernel  # noqa: E402
from isf.ipfo import answer_requests  # noqa: E402
from isf.ipfo_kernel import DONE, resume  # noqa: E402
from isf.lockstep import LockstepFitter  # noqa: E402
from isf.nearest import nearest_point, search_scratch  # noqa: E402

FITS = 32


@njit(cache=True)
def _unchanged(slots, grip, obj, hits, queries):
    """Add, per pyramid level, the running fits' contact points whose last answer is still their
    nearest object point (``hits``) and all of them (``queries``), at the state before a round."""
    status, level_of, current, last = slots[6], slots[7], slots[11], slots[14]
    scratch = search_scratch()
    for b in range(len(status)):
        if status[b] != kernel.RUNNING:
            continue
        level = level_of[b]
        rows, count = grip[4][level], grip[5][level]
        for i in range(count):
            g = rows[i]
            found = nearest_point(current[b, i, 0], current[b, i, 1], current[b, i, 2], -1, obj[0],
                                  obj[2], scratch, np.inf)[0]
            hits[level] += found == last[b, g]
            queries[level] += 1


def run_rounds(gripper, obj, proposals, forget: bool, count_hits: bool) -> dict:
    """All fits to the end, round by round: seconds per step, fit-iterations, and the counts of
    last answers still nearest; ``forget``: every last answer dropped before each round."""
    fitter = LockstepFitter(gripper, obj)
    for i, p in enumerate(proposals):
        fitter.add(i, p.T_object_gripper, p.q)
    slots, history, grip = fitter._slots, fitter._history, fitter._grip
    fit_params, ipfo_params = fitter._fit_params, fitter._ipfo_params
    work = kernel._work(len(grip[2]), len(obj.points))
    n_links = slots[2].shape[1]
    levels = fitter.config.levels
    hits, queries = np.zeros(levels, np.int64), np.zeros(levels, np.int64)
    seconds = np.zeros(3)
    fit_iterations = 0
    while np.any(slots[6] == kernel.RUNNING):
        if count_hits:
            _unchanged(slots, grip, fitter._obj, hits, queries)
        if forget:
            slots[14][:] = -1
        t0 = time.perf_counter()
        pairs, state, moments = kernel._prepare(slots, grip, fitter._obj, fit_params, ipfo_params,
                                                work, n_links)
        t1 = time.perf_counter()
        if len(pairs[0]):
            reply = resume(state, moments, ipfo_params, 0, False, np.zeros(state[1].shape), False,
                           state[2], state[3], state[4], state[5])
            if reply[0] != DONE:
                qps = [fitter._qp(b) for b in pairs[0].tolist()] if gripper.n_joints else None
                answer_requests(gripper, qps, state, moments, ipfo_params, reply)
        t2 = time.perf_counter()
        if len(pairs[0]):
            kernel.finish_round(slots, history, grip, fit_params, pairs, state)
        t3 = time.perf_counter()
        seconds += (t1 - t0, t2 - t1, t3 - t2)
        fit_iterations += len(pairs[0])
        slots[6][slots[6] > kernel.RUNNING] = kernel.EMPTY  # ended fits leave, as in the engine
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
    level_table = _common.markdown_table(
        ["pyramid level", "contact points matched", "last answer still the nearest"],
        [[level, int(queries[level]), f"{hits[level] / max(queries[level], 1):.1%}"]
         for level in range(len(queries))])
    note = (f"Gripper `{GRIPPER}`, {FITS} fits from uniform-sampler starts (seed 0) run to the end "
            f"in one lockstep batch; medians of {args.repeats} runs, per fit-iteration (wall "
            "time). Saved per query: (match from the tree's root - match) / the queries.")
    _common.finish("bench_rounds: where an ISF round's time goes",
                   ["### Steps of a round", note, table,
                    "### Searches from the last answer", level_table], started, header, args.out)


if __name__ == "__main__":
    main()
