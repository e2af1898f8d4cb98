"""Reproduce the paper's Table I: 60 samples per object with the paper's gripper.

Objects: the Stanford bunny and dragon (genesis-world wheel), the pybullet duck,
mug and random objects, the robosuite household meshes, and the YCB objects of
``shared/data/ycb`` when present (all fetched or read by :mod:`isf.assets`,
never shipped). Each object is scaled, as the paper did, "to fit into the
gripper range": uniformly, so that the middle of its three bounding-box extents
is 25 mm (the paper gripper opens 10-30 mm), and is sampled to at most 2000
points (the paper's objects had 740-3971 vertices).

Run:  python bench/table1.py [--repeats 5] [--objects bunny,dragon,...] [--out docs/table1.md]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

import isf  # noqa: E402
from isf import assets  # noqa: E402
from isf.samplers import RegretSampler  # noqa: E402

PAPER = {  # Table I of the paper: collision-free of 60, t_total (s), vertices
    "Hand": (53, 1.85, 1939), "Gun": (36, 2.45, 2287), "Car": (18, 1.68, 2166),
    "Oscar": (31, 2.03, 3684), "Dragon": (3, 5.61, 3971), "Bunny": (33, 1.56, 740),
    "Banana": (54, 3.82, 1723), "Screw Driver": (58, 1.71, 930), "Doraemon": (40, 1.84, 769),
}
PAPER_AVERAGE = (36.2, 2.33, 2022.1)
MIDDLE_EXTENT = 0.025  # metres
MAX_POINTS = 2000
DEFAULT_OBJECTS = ["bunny", "dragon", "duck", "mug", "random-000", "random-001", "random-002",
                   "bottle", "lemon"]


def object_names(requested: str | None) -> list[str]:
    if requested:
        return requested.split(",")
    names = list(DEFAULT_OBJECTS)
    try:
        names += assets.benchmark_objects("ycb")
    except isf.ISFError:
        print("# YCB folder not found: YCB rows skipped (set ISF_YCB_DIR)")
    return names


def load_scaled(name: str) -> isf.ObjectSurface:
    """The benchmark object scaled so its middle bounding-box extent is MIDDLE_EXTENT."""
    asset = assets.benchmark_object(name)
    mesh = trimesh.load(asset.path, force="mesh", process=False)
    extents = np.sort(mesh.extents * asset.scale)
    scale = asset.scale * MIDDLE_EXTENT / extents[1]
    return isf.load_object(asset.path, scale=scale, max_points=MAX_POINTS, name=name)


def run(name: str, gripper: isf.Gripper, repeats: int, samples: int) -> dict:
    obj = load_scaled(name)
    # the paper's sampler: k-means centres, uniformly random orientations
    runs = [isf.plan(gripper, obj, samples=samples, sampler=RegretSampler(orientation="random"), seed=seed)
            for seed in range(repeats)]
    free = [r.stats.collision_free for r in runs]
    totals = [r.stats.total_time for r in runs]
    errors = [np.mean([g.fit.mean_distance for g in r.grasps if g.collision_free] or [np.nan])
              for r in runs]
    return {
        "object": name, "vertices": obj.n_points, "free": statistics.median(free),
        "t_total": statistics.median(totals),
        "t_per_free": statistics.median(t / f if f else np.inf for t, f in zip(totals, free)),
        "error_mm": 1e3 * float(np.nanmedian(errors)),
    }


def table(rows: list[dict], samples: int, repeats: int) -> str:
    lines = [
        f"Paper gripper (paper-parallel), {samples} samples per object, regret sampler, "
        f"median of {repeats} run(s) (seeds 0..{repeats - 1}); machine: {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, OMP/OPENBLAS threads 1.",
        "",
        "| object | collision-free / 60 | t_total (s) | time per collision-free (ms) | vertices | mean fitting error of collision-free grasps (mm) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['object']} | {r['free']:g}/{samples} | {r['t_total']:.2f} | "
                     f"{1e3 * r['t_per_free']:.1f} | {r['vertices']} | {r['error_mm']:.3f} |")
    if rows:
        mean_free = np.mean([r["free"] for r in rows])
        mean_t = np.mean([r["t_total"] for r in rows])
        lines.append(f"| **average (isf)** | {mean_free:.1f}/{samples} | {mean_t:.2f} | "
                     f"{1e3 * mean_t / mean_free if mean_free else float('inf'):.1f} | "
                     f"{np.mean([r['vertices'] for r in rows]):.0f} | "
                     f"{np.nanmean([r['error_mm'] for r in rows]):.3f} |")
    f, t, v = PAPER_AVERAGE
    lines.append(f"| **average (paper, Matlab, 4 GHz)** | {f}/60 | {t:.2f} | 64.4 | {v:.0f} | - |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1, help="runs per object (median)")
    parser.add_argument("--samples", type=int, default=60)
    parser.add_argument("--objects", default=None, help="comma-separated benchmark names")
    parser.add_argument("--out", default=None, help="also write the table (markdown) here")
    args = parser.parse_args()
    gripper = isf.load_gripper("paper-parallel")
    rows = []
    for name in object_names(args.objects):
        started = time.perf_counter()
        rows.append(run(name, gripper, args.repeats, args.samples))
        print(f"# {name}: done in {time.perf_counter() - started:.1f} s", flush=True)
    text = table(rows, args.samples, args.repeats)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write("# Table I, reproduced\n\n" + text + "\n\nCommand: `python bench/table1.py "
                    f"--repeats {args.repeats}`\n")


if __name__ == "__main__":
    main()
