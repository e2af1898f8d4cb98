"""The collision repair's dense QPs solved by isf's dual active-set solver and by daqp.

The QPs are the ones the repair really solves: every call of
:func:`isf.repair.dense_qp.solve_dense_qp` from :mod:`isf.repair.clearance` is recorded while
``isf.plan`` plans with ``repair_collisions=True`` (regret sampler; the three-finger hand on the
YCB banana and tomato soup can, the paper gripper on the Stanford bunny and the YCB banana, the
Allegro hand on the YCB banana, the grippers and objects as ``bench_repair.py`` builds them).
Each recorded QP

    min 1/2 z^T H z + f^T z   s.t.   lower <= A z <= upper

is then solved in the same run, alternately, by

* **isf**: :func:`isf.repair.dense_qp.solve_dense_qp` as the repair calls it;
* **daqp**: ``daqp.solve(H, f, A, upper, lower)`` with the same rows, daqp's default primal
  tolerance (1e-6) and :data:`isf.repair.clearance.DAQP_PRIMAL_TOLERANCE`;
* **daqp, bounds**: daqp (the latter tolerance) with the rows that bound one variable (the
  slacks and the step's trust region and joint limits, :func:`isf.repair._step.step_qp`) given
  as simple bounds, the other rows as general constraints.

Reported: per solver the median and the worst time per QP (each QP's time is the least of
``--repeats`` calls), the ratio of the medians to isf's, the largest differences from isf's
answer over all QPs, relative (of the solution, max-norm over ``max(1, |z_isf|)``, and of the
objective over ``max(1, |objective|)``), the largest constraint violation of its own answers
``max(lower - A z, A z - upper, 0)`` (the QPs are in millimetres, see
``isf.repair.clearance.ClearanceRepair``), and how many QPs it did not solve.

Run from the repository root (needs ``pip install daqp`` and the YCB folder, ``ISF_YCB_DIR``):
    python bench/bench_repair_qp.py [--samples 30] [--seeds 2] [--repeats 7] [--out FILE]
                                    [--problems /tmp/repair_qps.pkl]
(``--problems``: the recorded QPs are data, keep them out of the repository).
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import time
from pathlib import Path
from typing import NamedTuple

import _common  # before numpy: pins BLAS/OpenMP threads
import daqp
import numpy as np
from bench_repair import configurations

import isf
from isf.repair import clearance
from isf.repair.dense_qp import solve_dense_qp

CONFIGURATIONS = ("three-finger/banana", "three-finger/soup can", "paper-parallel/bunny",
                  "paper-parallel/banana", "allegro/banana")
DAQP_SOLVED = (1, 2)  # daqp's exit flags of an optimal solution (2: one of several)


class Problem(NamedTuple):
    """One recorded QP ``min 1/2 z^T H z + f^T z, lower <= A z <= upper``."""

    H: np.ndarray
    """(n, n)."""
    f: np.ndarray
    """(n,)."""
    A: np.ndarray
    """(m, n)."""
    lower: np.ndarray
    """(m,), may hold -inf."""
    upper: np.ndarray
    """(m,), may hold inf."""


class Answer(NamedTuple):
    """A solver's answer to a :class:`Problem`."""

    z: np.ndarray
    """The solution, (n,)."""
    solved: bool
    """Whether the solver reports an optimal solution."""


def record(samples: int, seeds: int) -> dict[str, list[Problem]]:
    """The QPs the repair solves in plans of ``samples`` samples, seeds ``0..seeds-1``, per
    configuration."""
    problems: dict[str, list[Problem]] = {}
    original = clearance.solve_dense_qp
    for name, (gripper, obj) in configurations(CONFIGURATIONS).items():
        found = problems.setdefault(name, [])

        def recording(H, f, A, lower, upper, found=found, **kwargs):
            found.append(Problem(*(np.array(a, dtype=float) for a in (H, f, A, lower, upper))))
            return original(H, f, A, lower, upper, **kwargs)

        clearance.solve_dense_qp = recording
        try:
            for seed in range(seeds):
                isf.plan(gripper, obj, samples=samples, seed=seed, repair_collisions=True)
        finally:
            clearance.solve_dense_qp = original
        print(f"# {name}: {len(found)} QPs", flush=True)
    return problems


def solve_isf(p: Problem) -> Answer:
    result = solve_dense_qp(p.H, p.f, p.A, p.lower, p.upper)
    return Answer(result.x, result.status == "solved")


def solve_daqp(p: Problem, primal_tol: float = 1e-6) -> Answer:
    z, _, flag, _ = daqp.solve(p.H, p.f, p.A, p.upper, p.lower, primal_tol=primal_tol)
    return Answer(z, flag in DAQP_SOLVED)


def solve_daqp_tight(p: Problem) -> Answer:
    return solve_daqp(p, clearance.DAQP_PRIMAL_TOLERANCE)


def bounds_form(p: Problem) -> Problem:
    """``p`` with the rows that bound one variable by coefficient 1 as daqp's simple bounds: the
    bounds of every variable first (infinite where no row bounds it), then the other rows."""
    n = len(p.f)
    single = (np.count_nonzero(p.A, axis=1) == 1) & (np.abs(p.A).max(axis=1) == 1.0)
    lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
    for i in np.flatnonzero(single):
        (j,) = np.flatnonzero(p.A[i])
        lower[j], upper[j] = max(lower[j], p.lower[i]), min(upper[j], p.upper[i])
    rest = ~single
    return Problem(p.H, p.f, p.A[rest], np.concatenate([lower, p.lower[rest]]),
                   np.concatenate([upper, p.upper[rest]]))


def objective(p: Problem, z: np.ndarray) -> float:
    return float(0.5 * z @ p.H @ z + p.f @ z)


def violation(p: Problem, z: np.ndarray) -> float:
    Az = p.A @ z
    return float(max(0.0, np.max(p.lower - Az, initial=0.0), np.max(Az - p.upper, initial=0.0)))


def least_time(solve, problem: Problem, repeats: int) -> float:
    """The least wall time of ``repeats`` calls of ``solve(problem)``, seconds."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        solve(problem)
        best = min(best, time.perf_counter() - start)
    return best


SOLVERS = {"isf": (solve_isf, lambda p: p), "daqp, primal_tol 1e-6": (solve_daqp, lambda p: p),
           "daqp": (solve_daqp_tight, lambda p: p), "daqp, bounds": (solve_daqp_tight, bounds_form)}


def compare(problems: list[Problem], repeats: int) -> list[list[str]]:
    """One table row per solver (see the module docs)."""
    times = {name: [] for name in SOLVERS}
    worst = {name: [0.0, 0.0, 0.0] for name in SOLVERS}  # solution, objective, own violation
    unsolved = dict.fromkeys(SOLVERS, 0)
    for p in problems:
        reference = solve_isf(p)
        for name, (solve, form) in SOLVERS.items():
            q = form(p)
            answer = solve(q)
            times[name].append(least_time(solve, q, repeats))
            unsolved[name] += not answer.solved
            if answer.solved and reference.solved:
                size, value = max(1.0, np.max(np.abs(reference.z))), objective(p, reference.z)
                differences = (float(np.max(np.abs(answer.z - reference.z))) / size,
                               abs(objective(p, answer.z) - value) / max(1.0, abs(value)),
                               violation(p, answer.z))
                worst[name] = [max(a, b) for a, b in zip(worst[name], differences)]
    base = statistics.median(times["isf"])
    rows = []
    for name in SOLVERS:
        median = statistics.median(times[name])
        rows.append([name, f"{1e6 * median:.1f}", f"{1e6 * max(times[name]):.1f}",
                     f"{base / median:.2f}", *(f"{v:.1e}" for v in worst[name]),
                     str(unsolved[name])])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=30, help="samples per plan")
    parser.add_argument("--seeds", type=int, default=2, help="plans per configuration")
    parser.add_argument("--repeats", type=int, default=7, help="calls per QP (least time kept)")
    parser.add_argument("--out", default=None, help="also write the markdown report here")
    parser.add_argument("--problems", type=Path, default=None,
                        help="store the recorded QPs here, or read them when the file exists")
    args = parser.parse_args()
    if args.problems is not None and args.problems.exists():
        problems = pickle.loads(args.problems.read_bytes())
    else:
        problems = record(args.samples, args.seeds)
        if args.problems is not None:
            args.problems.write_bytes(pickle.dumps(problems))
    every = [p for found in problems.values() for p in found]
    solve_daqp(every[0])  # load daqp before timing
    header = ["solver", "median us per QP", "worst us", "speed-up over isf", "max rel. |dz|",
              "max rel. |d objective|", "max violation (mm)", "not solved"]
    lines = [_common.machine_description(), "",
             f"{len(every)} QPs ({', '.join(f'{k}: {len(v)}' for k, v in problems.items())}); "
             f"sizes n = {min(len(p.f) for p in every)}-{max(len(p.f) for p in every)}, "
             f"m = {min(len(p.A) for p in every)}-{max(len(p.A) for p in every)}", "",
             _common.markdown_table(header, compare(every, args.repeats))]
    report = "\n".join(lines)
    print(report)
    if args.out:
        with open(args.out, "w") as out:
            out.write(report + "\n")


if __name__ == "__main__":
    main()
