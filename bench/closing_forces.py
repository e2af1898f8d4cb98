"""Which links carry the grip: the quality top-5 grasps of one gripper, closed in the physics
test of ``isf validate``, with the share of the normal force on the contact surfaces' links.

For each grasp of each plan (60 samples, seed 0, as ``bench_hold.py`` plans them): the outcome
of :func:`isf.simulation.validate_grasp`; the share of the gripper-object normal force carried
by the links of the tagged contact surfaces at the end of the same closing, with gravity off
(MuJoCo's ``mj_contactForce``); and the depth at which the contact surfaces' links and the
other links sit in the object at the planned joints (the deepest contact of each group, the
simulation's convex parts). A grasp whose other links carry most of the force is held by them,
not by its contact surfaces (the Robotiq 2F-85's inner knuckles: docs/validate.md). Beside
them, the links isf's ranking expects to take the grip (``Grasp.closing_obstructed_by``,
:func:`isf.quality.closing.closing_obstructions`), and how often the two agree. With
``--every-valid`` every valid grasp of each plan is closed, not only the top 5 (the top 5 of
the quality ranking put the grasps with obstructions last).

Run from the repository root:
    python bench/closing_forces.py [--gripper robotiq-2f-85] [--objects ycb] [--share 0.2]
                                   [--every-valid]
"""

from __future__ import annotations

import _common  # noqa: F401  (thread pinning, before numpy)

import argparse
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

import bench_hold as bh
import isf
from isf.simulation import SimulationSettings, object_body, validate_grasp
from isf.simulation.grasp_test import close_fingers, set_joints
from isf.simulation.world import build_world


def _object_contacts(world, model, data):
    """(gripper body name, contact index) of every gripper-object contact."""
    for k in range(data.ncon):
        contact = data.contact[k]
        first, second = contact.geom1, contact.geom2
        if (first in world.object_geoms) == (second in world.object_geoms):
            continue
        geom = second if first in world.object_geoms else first
        yield model.body(model.geom_bodyid[geom]).name, k


def closing_record(gripper, body, grasp, settings: SimulationSettings) -> dict:
    """The closing of one grasp: contact-surface force share and depths (see the module)."""
    import mujoco

    q = np.asarray(grasp.q, dtype=float)
    surface_links = {surface.link for surface in gripper.surfaces}
    world = build_world(gripper, body, grasp.T_object_gripper, q, settings)
    model, data = world.model, mujoco.MjData(world.model)
    set_joints(world, data.qpos, q)
    mujoco.mj_forward(model, data)
    depth = {True: 0.0, False: 0.0}  # deepest penetration (m, >= 0) of surface / other links
    for link, k in _object_contacts(world, model, data):
        on_surface = link in surface_links
        depth[on_surface] = max(depth[on_surface], -float(data.contact[k].dist))
    close_fingers(gripper, world, data, q, settings)
    force = defaultdict(float)
    wrench = np.zeros(6)
    for link, k in _object_contacts(world, model, data):
        mujoco.mj_contactForce(model, data, k, wrench)
        force[link in surface_links] += float(wrench[0])
    total = force[True] + force[False]
    return {"outcome": validate_grasp(gripper, body, grasp.T_object_gripper, q, settings)
            .outcome.value,
            "surface_share": force[True] / total if total > 0 else None,
            "surface_depth": depth[True], "other_depth": depth[False]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gripper", default="robotiq-2f-85", choices=bh.GRIPPERS)
    parser.add_argument("--objects", default="ycb", help="as bench_hold.py's --objects")
    parser.add_argument("--share", type=float, default=0.2,
                        help="a grasp whose contact surfaces carry less of the force than this "
                        "share is counted as held by other links (default 0.2)")
    parser.add_argument("--deeper", type=float, default=0.0003,
                        help="margin, m, by which another link counts as deeper in the object "
                        "than the contact surfaces (default 0.0003)")
    parser.add_argument("--every-valid", action="store_true",
                        help="close every valid grasp of each plan, not only the top 5")
    args = parser.parse_args()
    settings = SimulationSettings(friction=bh.FRICTION)
    names = bh.object_names(args.objects)
    records = []
    with tempfile.TemporaryDirectory() as folder:
        gripper = bh.load(args.gripper, Path(folder))
        for name in names:
            obj = isf.open_object(bh.object_spec(name))
            body = object_body(obj.mesh_vertices, obj.mesh_faces, settings.mass)
            grasps = bh.plan(gripper, obj).grasps
            for rank, grasp in enumerate(grasps if args.every_valid else grasps[:bh.TOP]):
                if args.every_valid and not grasp.valid:
                    continue
                record = {"object": name, "rank": rank + 1,
                          "obstructed_by": grasp.closing_obstructed_by or (),
                          **closing_record(gripper, body, grasp, settings)}
                records.append(record)
                share = record["surface_share"]
                print(f"{name:16s} {rank + 1}  {record['outcome']:11s} contact-surface share "
                      f"{'-' if share is None else f'{share:.2f}'}  depth surfaces "
                      f"{1e3 * record['surface_depth']:.1f} mm, other links "
                      f"{1e3 * record['other_depth']:.1f} mm; isf: "
                      f"{', '.join(record['obstructed_by']) or 'no obstruction'}", flush=True)
    closed = [r for r in records if r["surface_share"] is not None]
    by_others = [r for r in closed if r["surface_share"] < args.share]
    deeper = [r for r in records if r["other_depth"] > r["surface_depth"] + args.deeper]
    held = sum(r["outcome"] == "held" for r in closed if r not in by_others)
    print(f"\n{args.gripper}: {len(closed)} of {len(records)} grasps end the closing in contact; "
          f"{len(by_others)} carry less than {args.share:.0%} of the normal force on the contact "
          f"surfaces, {sum(r['outcome'] == 'held' for r in by_others)} of them held, against "
          f"{held} of the other {len(closed) - len(by_others)}.")
    print(f"Another link deeper than the contact surfaces at the planned joints (by more than "
          f"{1e3 * args.deeper:.1f} mm): {len(deeper)} grasps, "
          f"{sum(r in deeper for r in by_others)} of the {len(by_others)} held by other links; "
          f"{sum(r['outcome'] == 'held' for r in deeper)} of the {len(deeper)} held, against "
          f"{sum(r['outcome'] == 'held' for r in records if r not in deeper)} of the other "
          f"{len(records) - len(deeper)}.")
    flagged = [r for r in records if r["obstructed_by"]]
    print(f"isf's closing obstructions (Grasp.closing_obstructed_by): {len(flagged)} grasps, "
          f"{sum(r in by_others for r in flagged)} of them held by other links in the simulation, "
          f"against {sum(r in by_others for r in records if r not in flagged)} of the other "
          f"{len(records) - len(flagged)}; {sum(r['outcome'] == 'held' for r in flagged)} of the "
          f"{len(flagged)} held, against "
          f"{sum(r['outcome'] == 'held' for r in records if r not in flagged)} of the other "
          f"{len(records) - len(flagged)}.")


if __name__ == "__main__":
    main()
