"""Reproduce the paper's Table I: 60 samples per object with the paper's gripper.

Objects (default): the Stanford bunny and dragon (genesis-world wheel), the pybullet duck and the
YCB Banana, Scissors and PowerDrill (``shared/data/ycb`` or ``ISF_YCB_DIR``), all fetched or read by
:mod:`isf.assets`, never shipped. Each object is scaled, as the paper did, "to fit into the
gripper range": uniformly, so that the middle of its three bounding-box extents is 25 mm (the
paper gripper opens 10-30 mm), and is sampled to at most 2000 points (the paper's objects had
740-3971 vertices). Sampler: the regret bandit with the paper's uniformly random orientations.

Every object runs once per mode of ``--modes`` (default ``8,w2,1``: 8 samples in lockstep in one
thread; one sample at a time on two worker threads, ``isf.plan(..., workers=2)``, the process
then allowed two CPUs; and 1, the paper's strictly sequential loop and ``isf.plan``'s default,
which serves as the reference for "results not worse"), seeds 0, 1, ... (the same seeds for
every mode). Reported per object and mode: ``t_total`` (``PlanStats.total_time``), the process
CPU time, the time per collision-free grasp, the collision-free count and the mean fitting
error of the collision-free grasps
(``FitResult.mean_distance``); medians over ``--repeats`` runs cut by ``--budget`` seconds per
configuration (at least one run), beside the paper's figures.

Run from the repository root:
    python bench/table1.py [--quick] [--repeats 5] [--modes 16,w2,1] [--objects bunny,duck]
"""

from __future__ import annotations

import _common

import time

import numpy as np

import isf
from isf.samplers import RegretSampler

GRIPPER = "paper-parallel"
PAPER = {  # Table I of the paper: collision-free of 60, t_total (s), vertices
    "Hand": (53, 1.85, 1939), "Gun": (36, 2.45, 2287), "Car": (18, 1.68, 2166),
    "Oscar": (31, 2.03, 3684), "Dragon": (3, 5.61, 3971), "Bunny": (33, 1.56, 740),
    "Banana": (54, 3.82, 1723), "Screw Driver": (58, 1.71, 930), "Doraemon": (40, 1.84, 769),
}
MAX_POINTS = 2000
DEFAULT_OBJECTS = ("bunny", "dragon", "duck", "ycb:Banana", "ycb:Scissors", "ycb:PowerDrill")
QUICK_OBJECTS, QUICK_SAMPLES = ("duck",), 20


def paper_sampler() -> RegretSampler:
    """The paper's sampler: k-means centres, uniformly random orientations, no start at the
    centre of mass."""
    return RegretSampler(orientation="random", com_share=0)


def measure(gripper, obj, samples: int, mode: _common.Mode, args) -> dict:
    _common.use_cpus(mode.workers)
    runs, failed = _common.run_repeats(
        lambda seed: _common.plan_once(gripper, obj, samples, seed, batch_size=mode.batch_size,
                                       workers=mode.workers, sampler=paper_sampler(),
                                       repair_collisions=args.repair, centring=args.repair),
        args.repeats, _common.budget_or_none(args), catch=(isf.ISFError,))
    row = _common.median_row(runs, failed, args.repeats)
    print(f"#   {obj.name}, {mode.label}: t_total (s) {_common.timing_cell(row)}, "
          f"{row.get('free', 0):g} collision-free", flush=True)
    return row


def _ok(row: dict | None) -> bool:
    return row is not None and "timing" in row


def _cell(row: dict | None, key: str, scale: float = 1.0, digits: int = 3) -> str:
    return _common.fmt(row[key] * scale, digits) if _ok(row) else "-"


def side_by_side(names, points, results, batches, samples: int) -> str:
    """One row per object: each quantity for every mode next to each other."""
    ref = batches[-1].label
    headers = ["object", "points"]
    for what in ("t_total (s)", "CPU (s)", "ms per collision-free", "collision-free",
                 "mean fit error of collision-free (mm)"):
        headers += [f"{what}, {b.label}" for b in batches]
    headers += [f"t_total({ref}) / t_total({b.label})" for b in batches[:-1]]
    headers += [f"CPU({ref}) / CPU({b.label})" for b in batches[:-1]]
    body = []
    for name in names:
        rows = [results.get((name, b)) for b in batches]
        line = [name, points.get(name, "-")]
        line += [_cell(r, "t_total") for r in rows] + [_cell(r, "cpu") for r in rows]
        line += [_cell(r, "per_free", 1e3) for r in rows]
        line += [f"{r['free']:g}/{samples}" if _ok(r) else "-" for r in rows]
        line += [_cell(r, "error", 1e3) for r in rows]
        for key in ("t_total", "cpu"):
            line += [_common.fmt(rows[-1][key] / r[key]) if _ok(r) and _ok(rows[-1])
                     else "-" for r in rows[:-1]]
        body.append(line)
    body.append(average_row(names, results, batches, samples))
    paper = _common.PAPER
    body.append(["**paper (average of 9 objects; Matlab, 4 GHz)**", f"{paper['vertices']:.0f}"]
                + [f"{paper['t_total_60']}"] * len(batches) + ["-"] * len(batches)
                + [f"{paper['ms_per_free']}"] * len(batches)
                + [f"{paper['free_of_60']}/60"] * len(batches) + ["-"] * len(batches)
                + ["-"] * 2 * (len(batches) - 1))
    return _common.markdown_table(headers, body)


def average_row(names, results, batches, samples: int) -> list[str]:
    """Means over the objects every mode measured (so the columns compare like with like)."""
    common = [n for n in names if all(_ok(results.get((n, b))) for b in batches)]
    line = [f"**average (isf, {len(common)} objects)**", "-"]
    if not common:
        return line + ["-"] * (5 * len(batches) + 2 * (len(batches) - 1))

    def mean(key: str, b: _common.Mode) -> float:
        return float(np.nanmean([results[(n, b)][key] for n in common]))

    t = {b: mean("t_total", b) for b in batches}
    cpu = {b: mean("cpu", b) for b in batches}
    free = {b: mean("free", b) for b in batches}
    line += [_common.fmt(t[b]) for b in batches] + [_common.fmt(cpu[b]) for b in batches]
    # the paper's "time per collision-free grasp" average: mean t_total / mean free count
    line += [_common.fmt(1e3 * t[b] / free[b]) if free[b] else "-" for b in batches]
    line += [f"{free[b]:.1f}/{samples}" for b in batches]
    line += [_common.fmt(1e3 * mean("error", b)) for b in batches]
    line += [_common.fmt(t[batches[-1]] / t[b]) for b in batches[:-1]]
    line += [_common.fmt(cpu[batches[-1]] / cpu[b]) for b in batches[:-1]]
    return line


def detail(names, results, batches, samples: int) -> str:
    """One row per object and mode: spread of t_total and the stage times."""
    body = []
    for name in names:
        for b in batches:
            r = results.get((name, b))
            if not _ok(r):
                body.append([name, b.label, "skipped (deadline)" if r is None else
                             _common.timing_cell(r)] + ["-"] * 6)
                continue
            body.append([name, b.label, _common.timing_cell(r), _common.fmt(r["cpu"]),
                         f"{r['setup']:.3f} / {r['fit']:.3f} / {r['collision']:.3f}",
                         f"{r['free']:g}/{samples}", f"{r['valid']:g}",
                         _common.fmt(r["error"] * 1e3), f"{r['iterations']:.1f}"])
    return _common.markdown_table(
        ["object", "mode", "t_total (s), median (min-max, n)", "CPU (s)",
         "set-up / ISF and repair / collision (s)", "collision-free", "valid", "mean fit error (mm)",
         "ISF iterations per sample"], body)


def paper_rows() -> str:
    return "The paper's own rows (its objects are not available here): " + ", ".join(
        f"{name} {free}/60 {t:.2f} s ({v} vertices)" for name, (free, t, v) in PAPER.items()
    ) + "."


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=60.0)
    parser.add_argument("--samples", type=int, default=60)
    parser.add_argument("--repair", action="store_true",
                        help="repair colliding fits and centre valid grasps (isf.plan's defaults); "
                             "without it the paper's Algorithm 3")
    parser.add_argument("--objects", default=None,
                        help="comma-separated benchmark names (default: "
                             + ",".join(DEFAULT_OBJECTS) + ")")
    parser.add_argument("--modes", default="8,w2,1",
                        help="comma-separated modes of isf.plan: a batch size (8: in lockstep, "
                             "one thread) or wN (N worker threads); default 8,w2,1; the LAST "
                             "one is the reference the others are compared with")
    args = parser.parse_args()
    names = args.objects.split(",") if args.objects else list(DEFAULT_OBJECTS)
    if args.quick:
        names = list(QUICK_OBJECTS) if not args.objects else names[:1]
        args.samples, args.repeats = min(args.samples, QUICK_SAMPLES), min(args.repeats, 1)
    try:
        batches = [_common.Mode.parse(m) for m in args.modes.split(",")]
    except ValueError as err:
        parser.error(f"--modes: {err}")
    batches = list(dict.fromkeys(batches))
    started = time.perf_counter()
    header = _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    gripper = isf.load_gripper(GRIPPER)
    results, points = {}, {}
    for name in names:  # every mode of an object before the next object
        obj = None
        for b in batches:
            if not deadline.allows(f"{name} with {b.label}"):
                continue
            if obj is None:
                obj, _ = _common.scaled_benchmark_object(name, max_points=MAX_POINTS)
                points[name] = obj.n_points
            results[(name, b)] = measure(gripper, obj, args.samples, b, args)
    sequential = "B=1: the paper's sequential loop; " if _common.Mode() in batches else ""
    repair = ("colliding fits repaired and valid grasps centred (isf.plan's defaults)"
              if args.repair else "no collision repair and no centring (the paper's Algorithm 3)")
    note = (f"Gripper `{GRIPPER}`, {args.samples} samples per object, regret sampler with random "
            f"orientations and no starts at the centre of mass (the paper's), {repair}, objects scaled to a "
            f"{_common.PAPER_GRIPPER_MIDDLE_EXTENT * 1e3:g} mm middle extent and sampled to at "
            f"most {MAX_POINTS} points; modes {', '.join(b.label for b in batches)} "
            f"(B: samples in lockstep in one thread, W: worker threads on as many CPUs; "
            f"{sequential}the last is the reference); seeds 0..n-1, up to "
            f"{args.repeats} runs per object and mode (budget {args.budget:g} s; n in the "
            "detail table). Medians over the runs; the average row is the mean of the objects' "
            "medians, and its time per collision-free grasp is mean t_total / mean count, as "
            "the paper's.")
    sections = ["### Table I: 60 samples per object", note,
                side_by_side(names, points, results, batches, args.samples),
                "**Detail** (per object and mode):",
                detail(names, results, batches, args.samples), paper_rows(), *deadline.note(),
                *_common.failure_notes([(f"{n}, {b.label}", r) for (n, b), r in results.items()])]
    _common.finish("table1: the paper's Table I, reproduced", sections, started, header, args.out)


if __name__ == "__main__":
    main()
