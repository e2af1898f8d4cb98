"""How planning time grows with the object's size and with the number of samples.

Paper gripper (``paper-parallel``), the Stanford bunny scaled uniformly to a 25 mm middle
bounding-box extent (as bench/table1.py does), ``isf.plan(..., sampler="regret")``:

* vs object size: 60 samples on the bunny sampled to about 1k, 2k, 10k, 50k and 200k surface
  points (voxel size searched so the count is within 10 %);
* vs samples: 15, 30, 60, 120 and 240 samples on the 2k-point bunny.

``t_total`` is ``PlanStats.total_time``: the planner's wall time of Algorithm 3 including its
set-up (sampler k-means, collision checker); loading the object (and building its KD-tree) is
outside it and listed separately. Medians over ``--repeats`` runs with seeds 0, 1, ...; a
configuration stops repeating once its runs took ``--budget`` seconds (at least one run), and the
tables show how many runs each median has. The growth ratio is t_total(200k) / t_total(2k).
``--batch-size`` sets ``isf.plan``'s ``batch_size`` (default: its default; 1 = the paper's
sequential loop); ``--workers N`` plans on N worker threads (``isf.plan(..., workers=N)``) and
lets the process run on N CPUs; ``--fit KEY=VALUE,...`` plans with those ISF parameters
(``isf.FitConfig``; default the paper's). ``--quick``: 2k and 10k points, 15 samples, one run
each.

Run from the repository root:
    python bench/bench_scaling.py [--quick] [--repeats 3] [--budget 20] [--batch-size 1] [--workers 2]
                                  [--sizes 2000,200000] [--sample-counts 60] [--fit tolerance=0.024]
"""

from __future__ import annotations

import _common

import time


import isf
from isf import assets

GRIPPER = "paper-parallel"
OBJECT = "bunny"
SIZES = (1_000, 2_000, 10_000, 50_000, 200_000)
SAMPLES = (15, 30, 60, 120, 240)
BASE_SIZE, BASE_SAMPLES = 2_000, 60
QUICK_SIZES, QUICK_SAMPLES, QUICK_BASE_SAMPLES = (2_000, 10_000), (15,), 15


class Objects:
    """The scaled bunny at each requested size, loaded on first use, with its load time (s)."""

    def __init__(self):
        _, self.scale = _common.scaled_benchmark_object(OBJECT, max_points=BASE_SIZE)
        self.path = assets.benchmark_object(OBJECT).path
        self.loaded: dict[int, tuple[isf.ObjectSurface, float]] = {}

    def get(self, n: int) -> tuple[isf.ObjectSurface, float]:
        if n not in self.loaded:
            t0 = time.perf_counter()
            found = _common.object_with_points(self.path, self.scale, n, OBJECT)
            search = time.perf_counter() - t0
            # the voxel search loads several times; time one load at the final voxel size
            t0 = time.perf_counter()
            obj = isf.load_object(self.path, scale=self.scale, voxel_size=found.spacing,
                                  name=found.name)
            self.loaded[n] = (obj, time.perf_counter() - t0)
            print(f"# {OBJECT} at {obj.n_points} points (voxel search {search:.1f} s)",
                  flush=True)
        return self.loaded[n]


def measure(gripper, obj, samples: int, args) -> dict:
    spacing = {"none": None, "auto": "auto"}.get(args.working_spacing)
    spacing = float(args.working_spacing) if spacing is None and args.working_spacing != "none" \
        else spacing
    runs, failed = _common.run_repeats(lambda seed: _common.plan_once(gripper, obj, samples, seed,
                                                                      config=args.fit,
                                                                      batch_size=args.batch_size,
                                                                      workers=args.workers,
                                                                      working_spacing=spacing),
                                       args.repeats, _common.budget_or_none(args),
                                       catch=(isf.ISFError,))
    row = _common.median_row(runs, failed, args.repeats)
    print(f"#   {obj.n_points} points, {samples} samples: t_total {_common.timing_cell(row)} s",
          flush=True)
    return row


def plan_order(sizes, sample_counts, base_samples: int) -> list[tuple[int, int]]:
    """(points, samples) configurations, most important first: the 2k/60 baseline, the largest
    object (for the growth ratio), then the other sizes, then the other sample counts."""
    order = [(BASE_SIZE, base_samples), (max(sizes), base_samples)]
    order += [(n, base_samples) for n in sizes] + [(BASE_SIZE, k) for k in sample_counts]
    return list(dict.fromkeys(order))


SKIPPED = "skipped (deadline)"


def size_table(rows: list[tuple[int, float, dict]], base_samples: int) -> str:
    body = [[n, _common.fmt(load), SKIPPED if r is None else _common.timing_cell(r)] + ["-"] * 9
            if r is None or "timing" not in r else [
        n, _common.fmt(load), f"{r['surface_points']:.0f}", _common.timing_cell(r),
        _common.fmt(r["cpu"]), f"{r['setup']:.3f}", f"{r['fit']:.3f}", f"{r['collision']:.3f}",
        f"{r['free']:g}/{base_samples}", _common.fmt(r["per_free"] * 1e3),
        _common.fmt(r["error"] * 1e3), _common.fmt(r["error_full"] * 1e3),
    ] for n, load, r in rows]
    body.append([f"{_common.PAPER['vertices']:.0f} (paper average, Matlab)", "-",
                 "-", f"{_common.PAPER['t_total_60']}", "-", "-", "-", "-",
                 f"{_common.PAPER['free_of_60']}/60", f"{_common.PAPER['ms_per_free']}", "-", "-"])
    return _common.markdown_table(
        ["object points", "load_object (s, not in t_total)", "points matched against",
         "t_total (s), median (min-max)", "CPU time (s)", "set-up (s)", "ISF (s)",
         "collision (s)", "collision-free", "ms per collision-free",
         "mean fit error of collision-free (mm)", "same, against every object point (mm)"], body)


def samples_table(rows: list[tuple[int, dict]]) -> str:
    body = [[k, SKIPPED if r is None else _common.timing_cell(r)] + ["-"] * 5
            if r is None or "timing" not in r else [
        k, _common.timing_cell(r), _common.fmt(r["cpu"]), _common.fmt(r["t_total"] / k * 1e3),
        f"{r['free']:g}/{k}", _common.fmt(r["per_free"] * 1e3), f"{r['setup']:.3f}",
    ] for k, r in rows]
    body.append([60, f"{_common.PAPER['t_total_60']} (paper average, Matlab)", "-",
                 _common.fmt(_common.PAPER["t_total_60"] / 60 * 1e3),
                 f"{_common.PAPER['free_of_60']}/60", _common.PAPER["ms_per_free"], "-"])
    return _common.markdown_table(
        ["samples", "t_total (s), median (min-max)", "CPU time (s)", "ms per sample",
         "collision-free", "ms per collision-free", "set-up (s)"], body)


def targets(results: dict, sizes, base_n: int, largest_n: int, base_samples: int) -> str:
    t, paper = _common.TARGETS, _common.PAPER
    ok = {key: row for key, row in results.items() if "timing" in row}
    base = ok.get((BASE_SIZE, base_samples))
    large = ok.get((max(sizes), base_samples))
    rows = []
    if base is not None:
        rows += [[f"t_total, {base_samples} samples, {base_n} points (s)", f"{base['t_total']:.3f}",
                  paper["t_total_60"], f"<= {t['t_total_60_paper_s']}",
                  _common.verdict(base["t_total"], t["t_total_60_paper_s"])],
                 ["ms per collision-free grasp (same runs)", _common.fmt(base["per_free"] * 1e3),
                  paper["ms_per_free"], f"<= {t['ms_per_free_paper']:g}",
                  _common.verdict(base["per_free"] * 1e3, t["ms_per_free_paper"])]]
    if base is not None and large is not None and largest_n != base_n:
        growth = large["t_total"] / base["t_total"]
        rows.append([f"growth t_total({largest_n} pts) / t_total({base_n} pts), "
                     f"{base_samples} samples",
                     f"{growth:.2f}", "-", f"<= {t['growth_200k_2k']}",
                     _common.verdict(growth, t["growth_200k_2k"])])
        rows.append(["same, on CPU time (less sensitive to a shared machine)",
                     f"{large['cpu'] / base['cpu']:.2f}", "-", "(wall time is the target)", "-"])
    return _common.markdown_table(["measure", "isf", "paper (Matlab)", "target", "met?"], rows)


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=60.0)
    parser.add_argument("--batch-size", type=int, default=_common.default_batch_size(),
                        help="batch_size of isf.plan (default: its default, "
                             f"{_common.default_batch_size()}; 1 = the paper's sequential loop)")
    parser.add_argument("--workers", type=int, default=1,
                        help="workers of isf.plan (default 1; N > 1 also lets the process use N "
                             "CPUs)")
    parser.add_argument("--working-spacing", default="auto",
                        help="working_spacing of isf.plan: 'auto' (its default), a spacing in "
                             "metres, or 'none' (match against every object point)")
    parser.add_argument("--sizes", default=None,
                        help="comma-separated object sizes, points (default "
                             + ",".join(map(str, SIZES)) + f"; must include {BASE_SIZE})")
    parser.add_argument("--sample-counts", default=None,
                        help="comma-separated sample counts of the samples sweep (default "
                             + ",".join(map(str, SAMPLES)) + ")")
    parser.add_argument("--fit", default=None, metavar="KEY=VALUE,...",
                        help="plan with isf.FitConfig(KEY=VALUE, ...) instead of the paper's "
                             "parameters, e.g. tolerance=0.024")
    args = parser.parse_args()
    if args.fit is not None:
        args.fit = _common.parse_config(parser, args.fit, "--fit", isf.FitConfig)
    sizes, sample_counts = (QUICK_SIZES, QUICK_SAMPLES) if args.quick else (SIZES, SAMPLES)
    try:
        sizes = tuple(int(n) for n in args.sizes.split(",")) if args.sizes else sizes
        sample_counts = (tuple(int(k) for k in args.sample_counts.split(","))
                         if args.sample_counts else sample_counts)
    except ValueError:
        parser.error("--sizes and --sample-counts take comma-separated integers")
    if BASE_SIZE not in sizes:
        parser.error(f"--sizes must include the baseline {BASE_SIZE}")
    base_samples = QUICK_BASE_SAMPLES if args.quick else BASE_SAMPLES
    if args.quick:
        args.repeats = min(args.repeats, 1)
    if args.workers < 1 or (args.workers > 1 and args.batch_size > 1):
        parser.error("--workers must be >= 1, and --batch-size 1 when it is more")
    _common.use_cpus(args.workers)
    started = time.perf_counter()
    header = _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    gripper = isf.load_gripper(GRIPPER)
    objects = Objects()
    results: dict[tuple[int, int], dict] = {}
    for n, k in plan_order(sizes, sample_counts, base_samples):
        if deadline.allows(f"{n} points x {k} samples"):
            results[(n, k)] = measure(gripper, objects.get(n)[0], k, args)

    def loaded(n: int) -> tuple[int, float]:
        if n in objects.loaded:
            obj, load = objects.loaded[n]
            return obj.n_points, load
        return n, float("nan")

    by_size = [(*loaded(n), results.get((n, base_samples))) for n in sizes]
    by_samples = [(k, results.get((BASE_SIZE, k))) for k in sample_counts]
    base_n, largest_n = loaded(BASE_SIZE)[0], loaded(max(sizes))[0]
    fit_note = "the paper's" if args.fit is None else f"`{_common.changed_fields(args.fit)}`"
    note = (f"Gripper `{GRIPPER}`, object: {OBJECT} scaled to a "
            f"{_common.PAPER_GRIPPER_MIDDLE_EXTENT * 1e3:g} mm middle extent, regret sampler, "
            f"batch size {args.batch_size}, {args.workers} worker thread(s) on as many CPUs, "
            f"working_spacing {args.working_spacing}, "
            f"ISF parameters: {fit_note}, "
            f"seeds 0..n-1, up to {args.repeats} runs per "
            f"configuration (budget "
            f"{args.budget:g} s). CPU time: process time around `isf.plan` (wall time minus "
            "waiting for a core on a shared machine).")
    sections = ["### Planning time vs. object size and samples", note,
                f"**vs. object size** ({base_samples} samples):", size_table(by_size, base_samples),
                f"**vs. samples** ({base_n} points):", samples_table(by_samples),
                "**Targets:**", targets(results, sizes, base_n, largest_n, base_samples),
                *deadline.note(),
                *_common.failure_notes([(f"{n} points x {k} samples", row)
                                        for (n, k), row in results.items()])]
    _common.finish("bench_scaling: planning time vs. object size and samples", sections,
                   started, header, args.out)


if __name__ == "__main__":
    main()
