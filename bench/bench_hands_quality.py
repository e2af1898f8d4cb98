"""Grasp quality of multi-fingered hands, before vs after the collision repair (isf.repair.clearance).

For each hand and YCB object (real size), one ``isf.plan`` of 60 samples (regret sampler, seed 0)
with ``repair_collisions=False`` (the paper's Algorithm 3: fit, then check) and one with
``repair_collisions=True`` (a colliding fit is repaired by :func:`isf.repair.clearance.repair_penetration`
and re-checked). Reported: collision-free grasps, valid grasps (collision-free and every contact
surface touching), the mean fitting error of the collision-free grasps
(``FitResult.mean_distance``), how many contact surfaces touch in the collision-free grasps
(mean), how many collision-free grasps have a link without contact surface touching the object
(``CollisionReport.clearance == 0``: the palm or a finger link carries part of the grasp), and the
wall time of the 60 samples with its fit / collision split (the repair counts as fit time).

Hands:

* ``three-finger``: the bundled hand.
* ``allegro``: the vendor Allegro hand tagged as docs/tutorial-register.md does
  (``suggest_contacts(points=64)`` + ``tag_urdf``): a 0.5 rad cap per fingertip facing the
  side the finger curls towards (see ``suggest_contacts``).
* ``allegro-palmar``: the same copy with each cap set by hand to the palmar side of the tip
  (``normal = (cos 0.35, 0, sin 0.35)`` in the tip frame: +x is palmar, +z distal), for
  comparison with the suggestion.

Run from the repository root (a machine shared with other jobs: times are indicative):
    python bench/bench_hands_quality.py [--quick] [--hands three-finger,allegro]
                                        [--objects TomatoSoupCan,MustardBottle,PottedMeatCan]
"""

from __future__ import annotations

import _common

import dataclasses
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf.assets import vendor_gripper
from isf.registration import suggest_approach, suggest_contacts, tag_urdf

SAMPLES = 60
SEED = 0
OBJECTS = ("TomatoSoupCan", "MustardBottle", "PottedMeatCan")
HANDS = ("three-finger", "allegro", "allegro-palmar")
PALMAR_TILT = 0.35  # rad from the palmar +x towards the distal +z of the tip frame


def allegro(folder: Path, palmar: bool) -> isf.Gripper:
    """The tagged Allegro copy (see the module docstring)."""
    src = vendor_gripper("allegro-right")
    contacts = suggest_contacts(src, points=64)
    if palmar:
        normal = (float(np.cos(PALMAR_TILT)), 0.0, float(np.sin(PALMAR_TILT)))
        contacts = [dataclasses.replace(c, normal=normal) for c in contacts]
    name = "allegro_palmar.urdf" if palmar else "allegro.urdf"
    preview = tag_urdf(src, folder / name, contacts, approach=suggest_approach(src))
    if not preview.ok:
        raise SystemExit(f"tagging the Allegro hand failed: {preview.problems}")
    return isf.load_gripper(preview.urdf_path)


def run(gripper: isf.Gripper, obj: isf.ObjectSurface, repair: bool) -> dict:
    result = isf.plan(gripper, obj, samples=SAMPLES, seed=SEED, repair_collisions=repair)
    s = result.stats
    free = result.collision_free_grasps()
    touching = [sum(v > 0.0 for v in g.fit.surface_contact.values()) for g in free]
    return {
        "free": s.collision_free, "valid": s.valid,
        "error": statistics.fmean(g.fit.mean_distance for g in free) if free else float("nan"),
        "touching": statistics.fmean(touching) if touching else float("nan"),
        "link_touch": sum(g.collision.clearance <= 0.0 for g in free),
        "t_total": s.total_time, "fit": s.fit_time, "collision": s.collision_time,
    }


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("--hands", default=",".join(HANDS), help=f"comma-separated, from {HANDS}")
    parser.add_argument("--objects", default=",".join(OBJECTS), help="comma-separated YCB names")
    args = parser.parse_args()
    hands = args.hands.split(",")
    unknown = sorted(set(hands) - set(HANDS))
    if unknown:
        parser.error(f"unknown hands {unknown}; choose from {HANDS}")
    objects = args.objects.split(",")[:1] if args.quick else args.objects.split(",")
    started = time.perf_counter()
    header = _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    rows = []
    with tempfile.TemporaryDirectory(prefix="isf-bench-hands-") as folder:
        makers = {"three-finger": lambda: isf.load_gripper("three-finger"),
                  "allegro": lambda: allegro(Path(folder), palmar=False),
                  "allegro-palmar": lambda: allegro(Path(folder), palmar=True)}
        grippers = {h: makers[h]() for h in hands}
        for name in objects:
            obj = isf.open_object(f"asset:ycb:{name}")
            for hand in hands:
                for repair in (False, True):
                    label = f"{hand} on {name} ({'after' if repair else 'before'})"
                    if not deadline.allows(label):
                        continue
                    row = run(grippers[hand], obj, repair)
                    row.update(hand=hand, object=name, repair=repair)
                    rows.append(row)
                    print(f"# {label}: {row['free']}/{SAMPLES} collision-free, {row['valid']} valid, "
                          f"{row['t_total']:.1f} s", flush=True)
    body = [[r["hand"], r["object"], "after" if r["repair"] else "before", f"{r['free']}/{SAMPLES}",
             r["valid"], _common.fmt(r["error"] * 1e3), _common.fmt(r["touching"], 2), r["link_touch"],
             f"{r['t_total']:.1f}", f"{r['fit']:.1f} / {r['collision']:.1f}"] for r in rows]
    table = _common.markdown_table(
        ["hand", "object", "repair", "collision-free", "valid", "mean fit error of collision-free (mm)",
         "surfaces touching (mean, collision-free)", "collision-free with a non-contact link touching",
         f"time per {SAMPLES} samples (s)", "fit / collision (s)"], body)
    text = (f"{SAMPLES} samples, regret sampler, seed {SEED}, default FitConfig, YCB objects at real size "
            "(`asset:ycb:NAME`, about 3000 points); 'before' = `repair_collisions=False`, 'after' = the "
            "default repair. One run per row.")
    _common.finish("bench_hands_quality: multi-fingered grasps before vs after the collision repair",
                   ["### Hands on YCB objects", text, table, *deadline.note()], started, header, args.out)


if __name__ == "__main__":
    main()
