"""Which collision repairs pay off, and could the ones that do not be stopped early?

Reads a corpus of the fits real plans hand to the repair (``bench/bench_repair.py --collect
CORPUS.pkl``), repairs each again with the default ``ClearanceRepair``, recording every step
(the deepest violation before it, and the deepest its QP promises after it, from the
linearised rows), and re-checks each repaired grasp with the planner's collision checker
(``isf.planning._evaluation.SampleJudge``: a repair counts only when that check passes). It prints per
configuration:

* the repairs by their depth before repair: how many, how many pass the re-check, their steps
  and CPU time, and the share of steps and CPU spent on repairs that do not pass;
* early-stopping rules (the issue's "early abandoning of samples that cannot win"), each run
  on the whole corpus: the steps and CPU time it saves, and the repairs that passed without it
  and fail with it (each a collision-free grasp lost from a plan), or the reverse.

Run from the repository root: ``python bench/repair_outcomes.py CORPUS.pkl`` (``--quick``: the
first 8 fits of each configuration).
"""

from __future__ import annotations

import time
from itertools import pairwise

import _common  # before numpy and isf: pins BLAS/OpenMP threads (see _common)
import numpy as np
from bench_repair import stored_configurations

import isf
from isf.warming import warm_up
from isf.planning._evaluation import SampleJudge

DEPTH_BINS_MM = (0.0, 1.0, 3.0, 6.0, 10.0, 15.0, 20.0, 30.0, np.inf)


def repair_all(judge: SampleJudge, cases: list, rule=None) -> list[dict]:
    """Repair every stored fit, stopped early where ``rule(steps, k)`` says so after step k.

    Returns per repair its depth before (m), CPU seconds, whether the planner's re-check passes
    the repaired grasp, and per step ``(deepest violation, deepest promised after the step)``
    (m). A rule stops a repair the way a failed QP does: the best state so far is returned.
    """
    repairer, steps = judge.repairer, []
    solve = type(repairer)._solve

    def recording(c_rows, gaps, a_rows, violation, element, q):
        x = solve(repairer, c_rows, gaps, a_rows, violation, element, q)
        promised = np.nan if x is None or not len(violation) else float((violation - a_rows @ x).max())
        steps.append((float(violation.max()) if len(violation) else np.nan, promised))
        return None if rule is not None and rule(steps, len(steps) - 1) else x

    repairer._solve = recording  # this instance only
    out = []
    try:
        for T, q, kwargs, _ in cases:
            steps.clear()
            start = time.process_time()
            result = repairer.repair(T, q, **kwargs)
            cpu = time.process_time() - start
            passed = judge.checker.check(result.T_object_gripper, result.q).collision_free
            out.append({"depth": result.depth_before, "cpu": cpu, "passed": passed,
                        "steps": list(steps)})
    finally:
        del repairer._solve
    return out


def depth_rows(name: str, repairs: list[dict]) -> tuple[list[list], str]:
    """Table rows of the repairs by depth before repair, and the failing repairs' share."""
    depth = np.array([r["depth"] for r in repairs]) * 1e3
    passed = np.array([r["passed"] for r in repairs])
    steps = np.array([len(r["steps"]) for r in repairs])
    cpu = np.array([r["cpu"] for r in repairs])
    rows = []
    bins = [(lo, hi, (depth >= lo) & (depth < hi))
            for lo, hi in pairwise(DEPTH_BINS_MM)]
    for label, sel in [(f"{lo:g}-{hi:g} mm", sel) for lo, hi, sel in bins] + [("all", depth >= 0)]:
        if sel.any():
            rows.append([name, label, sel.sum(), passed[sel].sum(), f"{steps[sel].mean():.1f}",
                         f"{1e3 * cpu[sel].mean():.1f}"])
    failed = ~passed
    share = (f"{name}: the repairs the re-check fails take "
             f"{100 * steps[failed].sum() / steps.sum():.0f} % of the steps and "
             f"{100 * cpu[failed].sum() / cpu.sum():.0f} % of the repair CPU time")
    return rows, share


def stall_rule(window: int, drop: float):
    """Stop once the deepest violation fell by less than ``drop`` (a fraction) over the last
    ``window`` steps."""
    def stops(steps, k):
        return k >= window and not steps[k][0] < (1.0 - drop) * steps[k - window][0]
    return stops


def promise_rule(target: float, factor: float, iterations: int):
    """Stop after a step when, at ``factor`` times the decrease the step's QP promises, the
    steps left could not bring the deepest violation below ``target`` (m)."""
    def stops(steps, k):
        worst, promised = steps[k]
        left = iterations - (k + 1)
        return worst - target > factor * left * max(worst - promised, 0.0)
    return stops


def rules(iterations: int) -> dict:
    """The early-stopping rules tried, by name."""
    out = {f"stall: less than {100 * d:g} % lower than {w} steps before": stall_rule(w, d)
           for w, d in ((3, 0.05), (4, 0.02))}
    for factor in (1.0, 4.0):
        out[f"promise: cannot reach 2 mm at {factor:g}x the QP's promise"] = \
            promise_rule(0.002, factor, iterations)
    return out


def compare(base: list[dict], other: list[dict]) -> list:
    """Steps and CPU saved (fractions of the base run's), passing repairs lost and gained."""
    steps = sum(len(r["steps"]) for r in base)
    cpu = sum(r["cpu"] for r in base)
    return [f"{100 * (1 - sum(len(r['steps']) for r in other) / steps):.0f} %",
            f"{100 * (1 - sum(r['cpu'] for r in other) / cpu):.0f} %",
            sum(a["passed"] and not b["passed"] for a, b in zip(base, other)),
            sum(b["passed"] and not a["passed"] for a, b in zip(base, other))]


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("corpus", help="the corpus file (bench/bench_repair.py --collect)")
    args = parser.parse_args()
    started, header = time.perf_counter(), _common.machine_description()
    warm_up()
    by_depth, shares, by_rule = [], [], []
    for name, gripper, obj, cases in stored_configurations(args.corpus):
        judge = SampleJudge(gripper, obj, isf.FitConfig())
        cases = cases[:8] if args.quick else cases
        repairs = repair_all(judge, cases)
        rows, share = depth_rows(name, repairs)
        by_depth += rows
        shares.append(share)
        for label, rule in rules(judge.repairer.config.iterations).items():
            by_rule.append([name, label, *compare(repairs, repair_all(judge, cases, rule))])
        for depth in (0.015, 0.020):  # a skipped repair saves all its steps, loses what passed
            skip = [{**r, "steps": [], "cpu": 0.0, "passed": False} if r["depth"] > depth else r
                    for r in repairs]
            by_rule.append([name, f"skip fits deeper than {1e3 * depth:g} mm",
                            *compare(repairs, skip)])
    _common.finish("repair_outcomes: which repairs pay off", [
        ("#### Repairs by depth before repair (passing: the planner's re-check finds the "
         "repaired grasp collision-free)"),
        _common.markdown_table(["configuration", "depth before", "repairs", "passing",
                                "steps (mean)", "CPU ms (mean)"], by_depth),
        "\n".join(f"- {s}" for s in shares),
        "#### Early-stopping rules, each run on the whole corpus",
        _common.markdown_table(["configuration", "rule", "steps saved", "CPU saved",
                                "passing repairs lost", "gained"], by_rule),
    ], started, header, args.out)


if __name__ == "__main__":
    main()
