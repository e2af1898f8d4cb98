"""Distinct grasps among the top 20, before and after the diversity pass (isf.planning.diversity).

For each gripper (the bundled ``paper-parallel``, ``flat-parallel``, ``three-finger`` and the
Franka hand tagged by ``isf tag``, ``_common.tagged_franka_hand``) and each YCB object of
``/work/shared/data/ycb`` (metres, as scanned), one plan of 60 samples, seed 0, is made with the
default :class:`isf.planning.diversity.Diversity` (1 cm, 30 degrees about the TCP, symmetry
detected), as ``isf.plan`` makes it by default, and its grasps are counted:

* **before**: distinct grasps among the top 20 of the plain ranking (the same grasps in
  :meth:`isf.Grasp.sort_key` order; a grasp within reach of a better one among them is not
  counted);
* **after**: distinct grasps among the top 20 that ``isf.plan`` returns (distinct grasps first
  within each tier: valid, collision-free, colliding);
* **valid after**: of those, the valid ones (collision-free, every contact surface touching);
* **distinct / 60**: distinct grasps among all samples, the most the object allows with this run.

Usage (from the repository root)::

    python bench/bench_diversity.py [--gripper NAME ...] [--object NAME ...] [--out FILE]
"""

from __future__ import annotations

import _common  # first: pins the thread variables

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf.planning.diversity import Diversity, distinct_first, symmetry_rotations

YCB = Path("/work/shared/data/ycb")
GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand")
TOP = 20
SAMPLES = 60
SEED = 0


def load(name: str, folder: Path) -> isf.Gripper:
    """A bundled gripper, or the tagged Franka hand (``franka-hand``)."""
    if name == "franka-hand":
        return _common.tagged_franka_hand(folder)
    return isf.load_gripper(name)


def count(result, gripper: isf.Gripper, diversity: Diversity) -> dict:
    """Distinct grasps of a plan made with ``diversity``, before and after its pass (module
    docstring): the plain ranking is the plan's grasps in :meth:`isf.Grasp.sort_key` order, the
    order :func:`isf.plan` ranks them in before the pass."""
    plain = sorted(result.grasps, key=lambda g: g.sort_key())
    T = np.array([g.T_object_gripper for g in plain]) @ gripper.T_root_tcp
    rotations = symmetry_rotations(gripper, result.diversity.symmetry)
    before = distinct_first(T[:TOP], rotations, diversity.distance, diversity.angle)
    distinct_top = [g for g in result.grasps[:TOP] if g.duplicate_of is None]
    return {
        "symmetry": result.diversity.symmetry,
        "before": int(np.sum(before.duplicate_of == 0)),
        "after": len(distinct_top),
        "valid_after": sum(g.valid for g in distinct_top),
        "distinct_all": sum(g.duplicate_of is None for g in result.grasps),
        "valid": result.stats.valid,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gripper", action="append", choices=GRIPPERS, default=None)
    parser.add_argument("--object", action="append", default=None, help="YCB name, e.g. Banana")
    parser.add_argument("--out", type=Path, default=None, help="also write the table here")
    args = parser.parse_args(argv)
    if not YCB.is_dir():
        print(f"{YCB} is absent: nothing to measure", file=sys.stderr)
        return 1
    objects = args.object or sorted(p.stem for p in YCB.glob("*.obj"))
    diversity = Diversity()
    lines = [f"| gripper | object | symmetry | before | after | valid after | distinct / "
             f"{SAMPLES} | valid / {SAMPLES} |", "|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    totals: dict[str, list[int]] = {}
    with tempfile.TemporaryDirectory() as folder:
        for name in args.gripper or GRIPPERS:
            gripper = load(name, Path(folder))
            for obj_name in objects:
                started = time.perf_counter()
                obj = isf.load_object(YCB / f"{obj_name}.obj")
                result = isf.plan(gripper, obj, samples=SAMPLES, seed=SEED, diversity=diversity)
                c = count(result, gripper, diversity)
                totals.setdefault(name, []).append(c["after"])
                line = (f"| {name} | {obj_name} | {c['symmetry']} | {c['before']} | {c['after']} "
                        f"| {c['valid_after']} | {c['distinct_all']} | {c['valid']} |")
                lines.append(line)
                print(line, f"<!-- {time.perf_counter() - started:.0f} s -->", flush=True)
    summary = [f"{name}: after >= 15 on {sum(a >= 15 for a in after)}/{len(after)} objects"
               for name, after in totals.items()]
    print("\n".join(summary))
    if args.out is not None:
        args.out.write_text("\n".join(lines + [""] + summary) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
