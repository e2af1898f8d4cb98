"""Stability-aware ranking on the YCB objects: what the quality ranking changes, at what cost.

For each gripper and object, one plan (60 samples, seed 0, no duplicate pass) is ranked both
ways from the same grasps: by quality (``rank="quality"``, the default) and by fitting error
(the paper's ``rank="fit"``: the same grasps sorted by :meth:`isf.Grasp.sort_key` without their
quality records). Reported per ranking: the top-1 grasp's epsilon and smallest gravity margin
(:mod:`isf.quality`, friction 0.5, 0.3 kg, 20 N grip), the top-5 means, and how many of the
top 5 are distinct poses (TCPs more than 1 cm or 30 degrees apart); the centring's share of
the plan (``stats.centring_time`` over ``stats.total_time``, wall time); the ranking overhead
(``stats.quality_time`` over the rest of the plan, wall time; and in CPU time: the ranking's
quality re-measured below, over the plan's CPU time less it) and the time per valid grasp of that
ranking's quality against computing every metric (epsilon, force closure, every load) of
every valid grasp, both on the plan's grasps in the same process (CPU time); and, for the parallel
grippers, the same
figures of the antipodal baseline (bench/antipodal_baseline.py, its top 5) scored by the same
metrics.

Usage:
    python bench/bench_quality.py [--gripper NAME ...] [--object NAME ...] [--samples 60]
"""

from __future__ import annotations

import _common  # first: pins the threads

import argparse
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import isf
from antipodal_baseline import plan_antipodal
from isf.quality import grasp_quality, grasps_quality, object_properties, quality_rank_key

YCB = Path("/work/shared/data/ycb")
GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand")


def distinct(poses: list[np.ndarray], distance=0.01, angle=np.pi / 6) -> int:
    """How many of ``poses`` (4, 4) are not within ``distance`` and ``angle`` of an earlier one."""
    kept: list[np.ndarray] = []
    for T in poses:
        if all(np.linalg.norm(T[:3, 3] - K[:3, 3]) > distance or np.arccos(np.clip(
                (np.trace(K[:3, :3].T @ T[:3, :3]) - 1) / 2, -1, 1)) > angle for K in kept):
            kept.append(T)
    return len(kept)


def summary(qualities, poses) -> dict:
    eps = [q.epsilon if q else 0.0 for q in qualities]
    margin = [q.min_margin if q else 0.0 for q in qualities]
    return {"eps1": eps[0] if eps else 0.0, "margin1": margin[0] if margin else 0.0,
            "eps5": float(np.mean(eps[:5])) if eps else 0.0,
            "margin5": float(np.mean(margin[:5])) if margin else 0.0,
            "holds1": bool(margin and margin[0] >= 1), "holds5": sum(m >= 1 for m in margin[:5]),
            "distinct5": distinct(poses[:5])}


def per_grasp_times(gripper, obj, grasps, config) -> tuple[float, float]:
    """CPU milliseconds per grasp (this process's, so that other processes on the machine do
    not count) of ``grasps``' quality as the ranking computes it (the centre of mass, the
    contact models of all grasps together, the sort by its key), and with every metric read
    (the whole record), each the best of 3."""
    if not grasps:
        return float("nan"), float("nan")
    poses = np.array([g.T_object_gripper for g in grasps])
    joints = np.array([g.q for g in grasps])
    times = {"ranked": [], "full": []}
    for _ in range(3):
        for kind in times:
            started = time.process_time()
            qualities = grasps_quality(gripper, obj, poses, joints, config, object_properties(obj))
            if kind == "full":
                for quality in qualities:
                    quality.to_dict()
            else:
                sorted(zip(qualities, grasps),
                       key=lambda pair: quality_rank_key(pair[0], pair[1].fit.mean_distance))
            times[kind].append(1e3 * (time.process_time() - started) / len(grasps))
    return min(times["ranked"]), min(times["full"])


def one(gripper, path: Path, samples: int) -> dict:
    obj = isf.load_object(path)
    cpu_started = time.process_time()
    result = isf.plan(gripper, obj, samples=samples, seed=0, diversity=None)
    cpu_plan = time.process_time() - cpu_started
    tcp = gripper.T_root_tcp
    by_quality = [g for g in result.grasps if g.valid]
    by_fit = sorted(by_quality, key=lambda g: replace(g, quality=None).sort_key())
    rest = result.stats.total_time - result.stats.quality_time
    ranked, full = per_grasp_times(gripper, obj, by_quality, result.quality)
    cpu_ranking = 1e-3 * ranked * len(by_quality) if by_quality else 0.0
    row = {"valid": result.stats.valid, "overhead": result.stats.quality_time / rest,
           "centring": result.stats.centring_time / result.stats.total_time,
           "cpu_overhead": cpu_ranking / max(cpu_plan - cpu_ranking, 1e-9),
           "ms_ranked": ranked, "ms_full": full,
           "quality": summary([g.quality for g in by_quality],
                              [g.T_object_gripper @ tcp for g in by_quality]),
           "fit": summary([g.quality for g in by_fit], [g.T_object_gripper @ tcp for g in by_fit])}
    if gripper.n_joints == 1 and len(gripper.surfaces) == 2:  # a parallel gripper
        started = time.perf_counter()
        baseline = plan_antipodal(gripper, obj, 5, seed=0, friction=0.5)
        config = result.quality
        properties = object_properties(obj)
        scored = [grasp_quality(gripper, obj, b.T_object_gripper, b.q, config, properties)
                  for b in baseline]
        row["baseline"] = summary(scored, [b.T_object_gripper @ tcp for b in baseline])
        row["baseline_time"] = time.perf_counter() - started
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--gripper", action="append", default=None)
    parser.add_argument("--object", action="append", default=None)
    parser.add_argument("--samples", type=int, default=60)
    args = parser.parse_args()
    objects = args.object or sorted(p.stem for p in YCB.glob("*.obj"))
    folder = Path(tempfile.mkdtemp())
    for name in args.gripper or GRIPPERS:
        gripper = _common.tagged_franka_hand(folder) if name == "franka-hand" else isf.load_gripper(name)
        rows = {}
        for obj in objects:
            rows[obj] = row = one(gripper, YCB / f"{obj}.obj", args.samples)
            line = [f"{name:14s} {obj:15s} valid {row['valid']:2d} overhead {row['overhead']:5.1%} "
                    f"(CPU {row['cpu_overhead']:5.1%}) centring {row['centring']:5.1%} "
                    f"ms/grasp {row['ms_ranked']:.2f} (every metric {row['ms_full']:.2f})"]
            for kind in ("fit", "quality", "baseline"):
                if kind in row:
                    s = row[kind]
                    line.append(f"{kind}: eps {s['eps1']:.3f}/{s['eps5']:.3f} margin "
                                f"{s['margin1']:.2f}/{s['margin5']:.2f} holds {int(s['holds1'])}/"
                                f"{s['holds5']} distinct {s['distinct5']}")
            print(" | ".join(line), flush=True)
        over = [r["overhead"] for r in rows.values()]
        ranked = [r["ms_ranked"] for r in rows.values()]
        full = [r["ms_full"] for r in rows.values()]
        cpu = [r["cpu_overhead"] for r in rows.values()]
        centring = [r["centring"] for r in rows.values()]
        print(f"{name}: overhead median {statistics.median(over):.1%} worst {max(over):.1%} "
              f"(CPU time: {statistics.median(cpu):.1%} / {max(cpu):.1%}); "
              f"ms per valid grasp median {np.nanmedian(ranked):.2f} worst {np.nanmax(ranked):.2f} "
              f"(every metric: {np.nanmedian(full):.2f} / {np.nanmax(full):.2f}); centring "
              f"{statistics.median(centring):.1%} / {max(centring):.1%} of the plan")
        for kind in ("fit", "quality", "baseline"):
            cells = [r[kind] for r in rows.values() if kind in r]
            if cells:
                print(f"  {kind:8s} top-1 holds {sum(c['holds1'] for c in cells)}/{len(cells)}, "
                      f"top-5 holds {sum(c['holds5'] for c in cells)}/{5 * len(cells)}, "
                      f"mean top-1 eps {np.mean([c['eps1'] for c in cells]):.3f} margin "
                      f"{np.mean([c['margin1'] for c in cells]):.2f}, distinct top-5 "
                      f"{np.mean([c['distinct5'] for c in cells]):.1f}", flush=True)


if __name__ == "__main__":
    main()
