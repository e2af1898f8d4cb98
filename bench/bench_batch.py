"""``isf batch`` on Dask: speed-up with worker processes, Dask's overhead per task, memory.

Runs the same batch (default 40 tasks: 10 YCB objects at real size x 2 grippers x 2 seeds, 60
samples each) into a fresh folder each time: once in this process without Dask
(``scheduler="synchronous"``, the reference), then on local Dask clusters of 1 and 2 worker
processes (``--workers``), started before the batch and passed as ``scheduler``. For each
run: the cluster's start-up; the wall time of ``run_batch`` (each worker's loading of the
compiled kernels included, as ``warm_time`` of its first task); the sum of the tasks' times in
their workers; the speed-up over the 1-worker cluster; and the overhead per task,
``(wall x workers - sum of task times) / tasks``: what Dask, the transfer of results, the
writing of the folder and the workers left idle at the end add to each task, compared with
the median task. Memory: each
worker process's peak resident set size (``max_rss_mb`` in the tasks table). Sizes: the
Parquet and plan file of a task, for the 100 000-task estimate of docs/batch.md.

Run from the repository root:
    python bench/bench_batch.py [--workers 1,2] [--samples 60] [--objects 10] [--seeds 2]
    python bench/bench_batch.py --quick        # 4 tasks of 10 samples: checks the script
"""

from __future__ import annotations

import _common

import json
import os
import statistics
import tempfile
import time
from pathlib import Path

GRIPPERS = ("flat-parallel", "three-finger")
YCB = ("Banana", "CrackerBox", "FoamBrick", "GelatinBox", "MasterChefCan", "MustardBottle",
       "PottedMeatCan", "PowerDrill", "Scissors", "TomatoSoupCan")


def _manifest(objects: int, seeds: int, samples: int) -> dict:
    return {"defaults": {"samples": samples},
            "cross": {"object": [f"asset:ycb:{name}" for name in YCB[:objects]],
                      "gripper": list(GRIPPERS), "seed": list(range(seeds))}}


def _run(manifest: dict, folder: Path, workers: int | None) -> dict:
    """One batch into ``folder``: its figures (seconds, MB, bytes)."""
    from isf.batch import SYNCHRONOUS, load_dataset, run_batch

    start_up = 0.0
    if workers is None:
        started = time.perf_counter()
        summary = run_batch(manifest, folder, scheduler=SYNCHRONOUS, progress=None)
        wall = time.perf_counter() - started
    else:
        import logging

        from distributed import LocalCluster

        _common.use_cpus(workers)
        started = time.perf_counter()
        with LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=None,
                          silence_logs=logging.ERROR) as cluster:
            start_up = time.perf_counter() - started
            started = time.perf_counter()
            summary = run_batch(manifest, folder, scheduler=cluster.scheduler_address, progress=None)
            wall = time.perf_counter() - started
    if not summary.ok:
        raise SystemExit(f"the batch failed:\n{summary.format()}")
    tasks = load_dataset(folder).tasks
    provenance = [json.loads(p)["worker"] for p in tasks["provenance"]]
    peak: dict[int, float] = {}
    for p in provenance:
        peak[p["pid"]] = max(peak.get(p["pid"], 0.0), p.get("max_rss_mb") or 0.0)
    n = len(tasks)
    processes = 1 if workers is None else workers
    return {
        "workers": "in this process" if workers is None else str(workers),
        "tasks": n, "wall": wall, "start_up": start_up, "task_sum": float(tasks["task_time"].sum()),
        "warm_sum": float(tasks["warm_time"].sum()),
        "median_task": float(statistics.median(tasks["task_time"] - tasks["warm_time"])),
        "overhead": (wall * processes - float(tasks["task_time"].sum())) / n,
        "memory": sorted(peak.values()),
        "parquet_bytes": statistics.mean(f.stat().st_size for f in (folder / "grasps").glob("*.parquet")),
        "plan_bytes": statistics.mean(f.stat().st_size for f in (folder / "plans").glob("*.json")),
        "grasps": int(tasks["grasps"].sum()),
    }


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0)
    parser.add_argument("--workers", default="1,2", help="worker processes of each Dask run (default 1,2)")
    parser.add_argument("--samples", type=int, default=60, help="samples per task (default 60)")
    parser.add_argument("--objects", type=int, default=len(YCB), help=f"YCB objects (default {len(YCB)})")
    parser.add_argument("--seeds", type=int, default=2, help="seeds per object and gripper (default 2)")
    args = parser.parse_args()
    if args.quick:
        args.samples, args.objects, args.seeds = 10, 2, 1
    # Dask's worker processes import this script again, and with it _common, which would pin
    # each of them to the same CPU: they keep the CPUs use_cpus gives the cluster instead
    os.environ["ISF_BENCH_CPU"] = "none"
    started = time.perf_counter()
    header = _common.machine_description()
    manifest = _manifest(args.objects, args.seeds, args.samples)
    counts = [int(w) for w in args.workers.split(",")]
    runs = []
    with tempfile.TemporaryDirectory(prefix="isf-bench-batch-") as tmp:
        for workers in [None, *counts]:
            name = "here" if workers is None else f"w{workers}"
            print(f"# running the batch {name}", flush=True)
            runs.append(_run(manifest, Path(tmp) / name, workers))
    base = next((r for r in runs if r["workers"] == "1"), None)
    rows = []
    for r in runs:
        speedup = "" if base is None or r["workers"] == "in this process" else \
            f"{base['wall'] / r['wall']:.2f}x"
        rows.append([r["workers"], r["tasks"], f"{r['start_up']:.1f}", f"{r['wall']:.1f}", f"{r['task_sum']:.1f}",
                     f"{r['warm_sum']:.1f}", speedup, f"{r['median_task']:.2f}",
                     f"{r['overhead']:.3f}", f"{100 * r['overhead'] / r['median_task']:.1f} %",
                     ", ".join(f"{m:.0f}" for m in r["memory"])])
    table = _common.markdown_table(
        ["workers", "tasks", "cluster start-up s", "wall s", "sum of task times s", "of which kernels loaded s",
         "speed-up over 1 worker", "median task s", "overhead per task s",
         "overhead / median task", "peak memory per process MB"], rows)
    last = runs[-1]
    sizes = (f"Per task ({args.samples} samples, {last['grasps'] / last['tasks']:.0f} grasps): "
             f"grasps Parquet file {last['parquet_bytes'] / 1e3:.0f} kB, plan file "
             f"{last['plan_bytes'] / 1e3:.0f} kB.")
    what = (f"{last['tasks']} tasks: {args.objects} YCB objects (real size) x {', '.join(GRIPPERS)} "
            f"x {args.seeds} seeds, {args.samples} samples each.")
    _common.finish("isf batch on Dask", [what, table, sizes], started, header, args.out)


if __name__ == "__main__":
    main()
