"""Time one ISF fit: median over repeated fits from seeded random starts.

Rows: the paper gripper (``paper-parallel``) on a ~2000-point object (the built-in cylinder and
the Stanford bunny scaled to 8 cm), and the bundled three-finger hand on a 5 cm sphere. Each fit
starts from the object point nearest a random direction, 5-10 mm off with a random orientation,
and runs alone (``isf.fit``: a batch of one in the lockstep engine). Reported: median wall time
of a fit (``FitResult.time``) and the process CPU time around it, ISF iterations, mean
point-to-plane distance and the share of fits that converged. The paper gives no per-fit time;
its 2.33 s per 60 samples (fit and collision check) is 38.8 ms per sample.

Run from the repository root:  python bench/bench_fit.py [--quick] [--repeats 30]
"""

from __future__ import annotations

import _common

import statistics
import time

import numpy as np
import trimesh

import isf
from isf.samplers import place_gripper, random_rotation

ROWS = (("paper-parallel", "cylinder r8 mm"), ("paper-parallel", "bunny 8 cm"),
        ("three-finger", "sphere r25 mm"))


def load(name: str) -> isf.ObjectSurface:
    if name == "cylinder r8 mm":
        return isf.open_object("shape:cylinder", max_points=2000)
    if name == "bunny 8 cm":
        bunny = isf.assets.benchmark_object("bunny").with_extent(0.08)
        return isf.load_object(bunny.path, scale=bunny.scale, max_points=2000, name=name)
    return isf.load_object(trimesh.creation.icosphere(4, 0.025), max_points=2000, name="sphere")


def time_fits(gripper, obj, repeats: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    times, cpus, iterations, distances, converged = [], [], [], [], 0
    for _ in range(repeats):
        centre = obj.points[rng.integers(obj.n_points)] + rng.normal(scale=0.005, size=3)
        T0 = place_gripper(gripper, centre, random_rotation(rng))
        c0 = time.process_time()
        result = isf.fit(gripper, obj, T0)
        cpus.append(time.process_time() - c0)
        times.append(result.time)
        iterations.append(result.iterations)
        distances.append(result.mean_distance)
        converged += result.converged
    return {"time": statistics.median(times), "cpu": statistics.median(cpus),
            "iterations": statistics.median(iterations),
            "distance": statistics.median(distances), "converged": converged, "n": repeats}


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=30, budget=0)
    args = parser.parse_args()
    rows = ROWS[:1] if args.quick else ROWS
    if args.quick:
        args.repeats = min(args.repeats, 5)
    started = time.perf_counter()
    header = _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    body, grippers = [], {}
    for gripper_name, name in rows:
        if not deadline.allows(f"{gripper_name} on {name}"):
            continue
        gripper = grippers.setdefault(gripper_name, isf.load_gripper(gripper_name))
        obj = load(name)
        r = time_fits(gripper, obj, args.repeats)
        body.append([gripper_name, name, obj.n_points, _common.fmt(r["time"] * 1e3),
                     _common.fmt(r["cpu"] * 1e3), f"{r['iterations']:g}",
                     _common.fmt(r["distance"] * 1e3), f"{r['converged']}/{r['n']}"])
    paper = _common.PAPER
    body.append(["paper-parallel (paper, Matlab)", "9 objects", f"{paper['vertices']:.0f}",
                 f"{_common.fmt(paper['t_total_60'] / 60 * 1e3)} per sample (fit + collision)",
                 "-", "-", "-", "-"])
    table = _common.markdown_table(
        ["gripper", "object", "points", "time per fit (ms, wall, median)", "CPU (ms, median)",
         "ISF iterations", "mean distance (mm)", "converged"], body)
    note = (f"Median of {args.repeats} fits per row, each alone (`isf.fit`), from seeded random "
            "starts 5-10 mm off the surface with random orientations.")
    _common.finish("bench_fit: one ISF fit at a time", ["### One fit", note, table,
                                                          *deadline.note()],
                   started, header, args.out)


if __name__ == "__main__":
    main()
