"""Time one ISF fit: median over repeated fits from seeded random starts.

Rows: the paper gripper (``paper-parallel``) on a ~2000-point object (the
built-in cylinder and the Stanford bunny scaled to 8 cm), and the bundled
three-finger hand on a 5 cm sphere. Each fit starts from the object point
nearest a random direction, 5-10 mm off with a random orientation.

Run:  python bench/bench_fit.py [--repeats 30]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

import isf  # noqa: E402
from isf.samplers import place_gripper, random_rotation  # noqa: E402


def objects() -> dict[str, isf.ObjectSurface]:
    out = {"cylinder r8 mm": isf.open_object("shape:cylinder", max_points=2000)}
    try:
        bunny = isf.assets.benchmark_object("bunny").with_extent(0.08)
        out["bunny 8 cm"] = isf.load_object(bunny.path, scale=bunny.scale, max_points=2000)
    except isf.ISFError as err:  # no registry access: skip the row, say so
        print(f"# bunny skipped: {err}")
    out["sphere r25 mm"] = isf.load_object(trimesh.creation.icosphere(4, 0.025), max_points=2000,
                                           name="sphere")
    return out


def time_fits(gripper, obj, repeats: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    times, iterations, distances, converged = [], [], [], 0
    for _ in range(repeats):
        centre = obj.points[rng.integers(obj.n_points)] + rng.normal(scale=0.005, size=3)
        T0 = place_gripper(gripper, centre, random_rotation(rng))
        result = isf.fit(gripper, obj, T0)
        times.append(result.time)
        iterations.append(result.iterations)
        distances.append(result.mean_distance)
        converged += result.converged
    return {"time_ms": 1e3 * statistics.median(times), "iterations": statistics.median(iterations),
            "distance_mm": 1e3 * statistics.median(distances), "converged": converged, "n": repeats}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    import isf.assets  # noqa: F401

    rows = []
    objs = objects()
    for gripper_name, names in (("paper-parallel", ["cylinder r8 mm", "bunny 8 cm"]),
                                ("three-finger", ["sphere r25 mm"])):
        gripper = isf.load_gripper(gripper_name)
        for name in names:
            if name in objs:
                rows.append((gripper_name, name, objs[name].n_points,
                             time_fits(gripper, objs[name], args.repeats)))
    print(f"median of {args.repeats} fits each, OMP/OPENBLAS threads 1, {os.cpu_count()} cores")
    print("| gripper | object | points | time per fit (ms) | ISF iterations | mean distance (mm) | converged |")
    print("|---|---|---|---|---|---|---|")
    for gripper_name, name, n, r in rows:
        print(f"| {gripper_name} | {name} | {n} | {r['time_ms']:.1f} | {r['iterations']:g} | "
              f"{r['distance_mm']:.3f} | {r['converged']}/{r['n']} |")


if __name__ == "__main__":
    main()
