"""What the regret sampler's starts at the centre of mass change in a plan, at what cost.

For each gripper and YCB object (real size) and seed, one ``isf.plan`` of 60 samples with
``RegretSampler(com_share=0)`` (the paper's starts: cluster centres only) and one with the
default ``com_share`` (every second start at the object's centre of mass), the two alternating
in one process. With ``--hear-quality`` the pair is the default sampler and
``RegretSampler(hear_quality=True)`` (the bandit hears whether each valid grasp is expected
to hold) instead. Reported per gripper and setting, summed or taken as medians over the plans:
valid grasps, valid grasps whose contacts' centroid lies within 20 mm of the centre of mass
(``GraspQuality.com_offset``), valid grasps the quality ranking expects to hold
(:func:`isf.quality.expected_to_hold`), the top-5 grasps' median ``com_offset``, and the
plan's wall time (``PlanStats.total_time``) with the paired ratio of the second setting to
the first (median and worst). Whether the grasps hold is for ``bench/bench_hold.py``
(physics) to say.

Needs the YCB meshes (``../shared/data/ycb`` or ``$ISF_YCB_DIR``).

Run from the repository root:
    python bench/bench_starts.py [--grippers flat-parallel,franka-hand] [--objects Banana,...]
                                 [--seeds 2] [--hear-quality]
"""

from __future__ import annotations

import _common  # first: pins the threads

import argparse
import statistics
import tempfile
import warnings
from pathlib import Path

import numpy as np

import isf
from bench_hold import OBJECTS, load
from isf.quality import expected_to_hold
from isf.samplers.regret import RegretSampler

GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand")
NEAR = 0.02
"""A valid grasp is near the centre of mass when its contacts' centroid is within this, m."""


SETTINGS = {"paper": {"com_share": 0.0}, "default": {}, "hearing": {"hear_quality": True}}
"""The ``RegretSampler`` parameters of each setting compared."""


def measure(gripper, obj, seed: int, setting: str) -> dict:
    """One plan's figures with the sampler of ``setting`` (:data:`SETTINGS`)."""
    result = isf.plan(gripper, obj, samples=60, seed=seed,
                      sampler=RegretSampler(**SETTINGS[setting]))
    valid = [g for g in result.grasps if g.valid]
    offsets = [g.quality.com_offset for g in valid]
    holding = sum(expected_to_hold(g.quality, closing_obstructed=bool(g.closing_obstructed_by))
                  for g in valid)
    return {"valid": len(valid), "near": sum(o < NEAR for o in offsets), "holding": holding,
            "top5": float(np.median(offsets[:5])) if offsets else float("nan"),
            "time": result.stats.total_time}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grippers", default=",".join(GRIPPERS))
    parser.add_argument("--objects", default=",".join(OBJECTS))
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--hear-quality", action="store_true",
                        help="compare the default sampler with one hearing the quality")
    args = parser.parse_args()
    first, second = ("default", "hearing") if args.hear_quality else ("paper", "default")
    # paper-parallel opens less than every real-size YCB object is wide: isf says so each plan
    warnings.simplefilter("ignore", isf.ObjectSizeWarning)
    default = RegretSampler().com_share
    print(_common.machine_description())
    print(f"60 samples, seeds 0..{args.seeds - 1}; 'paper': com_share=0, 'default': "
          f"com_share={default}, 'hearing': hear_quality=True; near: contacts within "
          f"{1000 * NEAR:.0f} mm of the centre of mass; holding: expected to hold")
    rows = []
    with tempfile.TemporaryDirectory(prefix="isf-bench-starts-") as folder:
        for name in args.grippers.split(","):
            gripper = load(name, Path(folder))
            isf.plan(gripper, isf.open_object("shape:box"), samples=4, seed=0)  # kernels ready
            runs: dict[str, list[dict]] = {first: [], second: []}
            for obj_name in args.objects.split(","):
                obj = isf.open_object(f"asset:ycb:{obj_name}")
                for seed in range(args.seeds):
                    for label in (first, second) if seed % 2 == 0 else (second, first):
                        runs[label].append(measure(gripper, obj, seed, label))
                    a, b = runs[first][-1], runs[second][-1]
                    print(f"# {name} {obj_name} seed {seed}: valid {a['valid']} -> {b['valid']}, "
                          f"near {a['near']} -> {b['near']}, holding {a['holding']} -> "
                          f"{b['holding']}, top-5 offset {1000 * a['top5']:.0f} -> "
                          f"{1000 * b['top5']:.0f} mm, time {a['time']:.2f} -> {b['time']:.2f} s",
                          flush=True)
            ratios = [b["time"] / a["time"] for a, b in zip(runs[first], runs[second])]
            for label, plans in runs.items():
                rows.append([name, label, len(plans), sum(r["valid"] for r in plans),
                             sum(r["near"] for r in plans), sum(r["holding"] for r in plans),
                             _common.fmt(1000 * float(np.nanmedian([r["top5"] for r in plans]))),
                             _common.fmt(statistics.median(r["time"] for r in plans)),
                             "" if label == first else
                             f"{statistics.median(ratios):.2f} (worst {max(ratios):.2f})"])
    print(_common.markdown_table(
        ["gripper", "starts", "plans", "valid grasps", "valid within 20 mm of the centre of mass",
         "valid expected to hold", "top-5 median distance (mm)", "median plan time (s)",
         f"time ratio {second} / {first}"], rows))


if __name__ == "__main__":
    main()
