"""Planning time of multi-fingered hands: the bundled three-finger hand and the Allegro hand.

60 samples (regret sampler) per hand and object; objects are YCB objects when the YCB folder is
present (``isf.assets.benchmark_objects("ycb")``; set ``ISF_YCB_DIR``), else built-in shapes
enlarged 3x to hand size; each is sampled to at most 2000 surface points as in the paper.

The Allegro hand (``isf.assets.vendor_gripper("allegro-right")``, example-robot-data) carries no
isf tags, so this script writes a tagged copy into a temporary folder: the ``isf`` namespace on
``<robot>``, ``<isf:gripper palm_link="palm_link" approach="1 0 0"/>`` (the fingers flex towards
the palm link's +x) and one ``<isf:contact>`` per fingertip link (``link_*_tip``, whose collision
geometry is a 12 mm sphere): a cap of half-angle 0.6 rad around the direction from the tip
towards the palm centre (the centroid of the palm's collision box) at the initial configuration
(isf's default, the middle of the joint limits), 128 points per tip. The vendor's
``package://example-robot-data/...`` mesh paths are resolved with ``package_dirs``.

Reported per hand and object: collision-free grasps of 60, mean fitting error of the
collision-free grasps (``FitResult.mean_distance``), ``t_total`` (``PlanStats.total_time``) and
time per collision-free grasp; medians over ``--repeats`` runs (seeds 0, 1, ...) cut by
``--budget`` seconds per configuration (at least one run).

``--modes`` lists how ``isf.plan`` runs the samples, one row each (default ``w2,1``: one at a
time on two worker threads, ``workers=2``, the process then allowed two CPUs; and 1, the paper's
sequential loop, ``isf.plan``'s default); the last mode is the reference of the speed-up
column; ``--objects N`` runs the first N objects only; ``--quick``: one object, 15 samples, one
run. ``--fit KEY=VALUE,...`` plans both hands with
``isf.FitConfig(KEY=VALUE, ...)`` instead of the paper's parameters (e.g.
``finger_damping=1e-6``, a diagnostic for finger QPs that fail to converge on a 16-joint hand,
or ``tolerance=0.024``). ``--repair KEY=VALUE,...`` plans with
``isf.RepairConfig(KEY=VALUE, ...)`` instead of the default repair (e.g.
``max_rows=12,activation=0.008``, the setting docs/hands.md compares with the default).

Run from the repository root:
    python bench/bench_hands.py [--quick] [--repeats 3] [--budget 20] [--hands allegro-right]
                                [--objects 1] [--modes w2,1] [--fit finger_damping=1e-6]
                                [--repair max_rows=12,activation=0.008]
"""

from __future__ import annotations

import _common

import re
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf import assets

SAMPLES = 60
QUICK_SAMPLES = 15
MAX_POINTS = 2000
YCB_OBJECTS = ("ycb:Banana", "ycb:MustardBottle", "ycb:PottedMeatCan")
SHAPE_OBJECTS = ("shape:cylinder", "shape:box", "shape:sphere")
SHAPE_SCALE = 3.0  # the built-in shapes suit a 1-3 cm jaw; hands need larger objects
ALLEGRO = "allegro-right"
ALLEGRO_PALM = "palm_link"
ALLEGRO_APPROACH = "1 0 0"  # flexion joints turn about +y and curl the fingers towards +x
TIP_MAX_ANGLE = 0.6  # rad
TIP_POINTS = 128


# --------------------------------------------------------------------------- the Allegro copy


def _package_dirs(urdf: Path, text: str) -> dict[str, str]:
    """``{package: folder}`` for the ``package://`` URIs of ``text``: the ancestor folder of
    ``urdf`` named like the package (the vendor's install layout)."""
    dirs = {}
    for package in sorted(set(re.findall(r"package://([^/\"']+)/", text))):
        folder = next((p for p in urdf.parents if p.name == package), None)
        if folder is None:
            raise SystemExit(f"cannot find the folder of package://{package}/ above {urdf}")
        dirs[package] = str(folder)
    return dirs


def _tag(text: str, normals: dict[str, np.ndarray]) -> str:
    """``text`` with the isf namespace, the gripper tag and one contact tag per tip link."""
    tagged = re.sub(r"<robot\b", '<robot xmlns:isf="urn:isf:gripper:1"', text, count=1)
    tags = [f'  <isf:gripper palm_link="{ALLEGRO_PALM}" approach="{ALLEGRO_APPROACH}"/>']
    for link, n in normals.items():
        tags.append(f'  <isf:contact name="{link}" link="{link}" normal="{n[0]:.6f} {n[1]:.6f} '
                    f'{n[2]:.6f}" max_angle="{TIP_MAX_ANGLE}" points="{TIP_POINTS}"/>')
    head, sep, tail = tagged.rpartition("</robot>")
    if not sep:
        raise SystemExit("the Allegro URDF has no </robot>: the vendor file changed")
    return head + "\n".join(tags) + "\n" + sep + tail


def tagged_allegro(folder: Path) -> isf.Gripper:
    """Write a tagged copy of the vendor Allegro URDF into ``folder`` and load it.

    Two passes: a provisional tag (normal +x) loads the hand so isf's kinematics give the tip
    and palm poses at the initial configuration; the final tags then use, per tip, the direction
    towards the palm centre expressed in the tip link's frame.
    """
    source = assets.vendor_gripper(ALLEGRO)
    text = source.read_text()
    tips = re.findall(r'<link\s+name="([^"]+_tip)"', text)
    if not tips:
        raise SystemExit("the Allegro URDF has no *_tip links: the vendor file changed")
    package_dirs = _package_dirs(source, text)
    path = folder / f"{ALLEGRO}-isf.urdf"

    path.write_text(_tag(text, {t: np.array([1.0, 0.0, 0.0]) for t in tips}))
    provisional = isf.load_gripper(path, package_dirs=package_dirs)
    poses = provisional.link_poses(provisional.q_initial)
    palm = [g.vertices for g in provisional.geometries if g.link == ALLEGRO_PALM]
    centre_gripper = poses[ALLEGRO_PALM][:3, :3] @ np.concatenate(palm).mean(axis=0) \
        + poses[ALLEGRO_PALM][:3, 3]
    normals = {}
    for tip in tips:
        T = poses[tip]
        towards = T[:3, :3].T @ (centre_gripper - T[:3, 3])
        normals[tip] = towards / np.linalg.norm(towards)
    path.write_text(_tag(text, normals))
    gripper = isf.load_gripper(path, package_dirs=package_dirs)
    print(f"# tagged {ALLEGRO}: {len(tips)} tips, {gripper.n_joints} joints, "
          f"{gripper.n_points} contact points, normals (tip frames): "
          + ", ".join(f"{t} {np.round(n, 2)}" for t, n in normals.items()), flush=True)
    return gripper


# --------------------------------------------------------------------------- benchmark


def load_objects(count: int) -> tuple[list[isf.ObjectSurface], str]:
    """The benchmark objects and a note on where they came from."""
    why = "objects missing"
    try:
        available = set(assets.benchmark_objects("ycb"))
    except isf.ISFError as err:
        available, why = set(), str(err)
    names = [n for n in YCB_OBJECTS if n in available]
    if names:
        note = "YCB objects (real size)"
        objects = [isf.open_object(f"asset:{n}", max_points=MAX_POINTS) for n in names]
    else:
        note = (f"no YCB folder ({why}): built-in "
                f"shapes scaled {SHAPE_SCALE:g}x")
        objects = [isf.open_object(s, scale=SHAPE_SCALE, max_points=MAX_POINTS)
                   for s in SHAPE_OBJECTS]
    return objects[:count], note


def bench(hand: str, gripper, obj, mode: _common.Mode, args) -> dict:
    _common.use_cpus(mode.workers)
    runs, failed = _common.run_repeats(
        lambda seed: _common.plan_once(gripper, obj, args.samples, seed, args.fit,
                                       batch_size=mode.batch_size, workers=mode.workers,
                                       repair_collisions=args.repair),
        args.repeats, _common.budget_or_none(args), catch=(isf.ISFError,))
    row = _common.median_row(runs, failed, args.repeats)
    row["hand"], row["object"], row["points"], row["mode"] = hand, obj.name, obj.n_points, mode
    print(f"#   {hand} on {obj.name}, {mode.label}: t_total (s) {_common.timing_cell(row)}, "
          f"{row.get('free', 0):g} collision-free", flush=True)
    return row


def report(rows: list[dict], note: str, args, deadline) -> list[str]:
    targets = {"three-finger": _common.TARGETS["t_total_60_three_finger_s"],
               ALLEGRO: _common.TARGETS["t_total_60_allegro_s"]}
    reference = {(r["hand"], r["object"]): r for r in rows if r["mode"] == args.modes[-1]}

    def speed_up(r: dict) -> str:
        ref = reference.get((r["hand"], r["object"]))
        return _common.fmt(ref["t_total"] / r["t_total"]) if ref and "timing" in ref else "-"

    body = [[r["hand"], r["object"], r["points"], r["mode"].label,
             _common.timing_cell(r) if "failed" in r else "skipped (deadline)"] + ["-"] * 10
            if "timing" not in r else [
        r["hand"], r["object"], r["points"], r["mode"].label, f"{r['free']:g}/{args.samples}",
        f"{r['valid']:g}",
        _common.fmt(r["error"] * 1e3), _common.timing_cell(r), _common.fmt(r["cpu"]),
        _common.fmt(r["per_free"] * 1e3), f"{r['fit']:.2f} / {r['collision']:.2f}",
        f"{r['iterations']:.0f}", speed_up(r), f"<= {targets[r['hand']]:g}",
        _common.verdict(r["t_total"], targets[r["hand"]]),
    ] for r in rows]
    paper = _common.PAPER
    body.append(["paper (parallel jaw only; Matlab)", "9 objects", f"{paper['vertices']:.0f}", "-",
                 f"{paper['free_of_60']}/60", "-", "-", f"{paper['t_total_60']}", "-",
                 f"{paper['ms_per_free']}", "-", "-", "-", "-", "-"])
    table = _common.markdown_table(
        ["hand", "object", "points", "mode", "collision-free", "valid (all tips touch)",
         "mean fit error of collision-free (mm)", "t_total (s), median (min-max)",
         "CPU time (s)", "ms per collision-free",
         "ISF and repair / collision time (s), summed over threads", "ISF iterations per sample",
         f"t_total({args.modes[-1].label}) / t_total", "target t_total (s)", "met?"], body)
    fit = ("the default `FitConfig`" if args.fit is None else
           f"`{_common.changed_fields(args.fit)}` (NOT the default `FitConfig`)")
    repair = ("the default repair" if args.repair is None else
              f"`{args.repair}` (NOT the default repair)")
    text = (f"{args.samples} samples, regret sampler, modes "
            f"{', '.join(m.label for m in args.modes)} (B: samples in lockstep in one thread, W: "
            f"worker threads on as many CPUs), {fit}, {repair}, "
            f"objects: {note}, at most "
            f"{MAX_POINTS} points; "
            f"up to {args.repeats} runs per row (budget {args.budget:g} s). CPU time: process "
            "time around `isf.plan`. Allegro: tagged copy of "
            f"`{ALLEGRO}` as described in `bench/bench_hands.py`.")
    failures = _common.failure_notes([(f"{r['hand']} on {r['object']}", r) for r in rows])
    return ["### Multi-fingered hands", text, table, *deadline.note(), *failures]


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=60.0)
    parser.add_argument("--hands", default="three-finger,allegro-right",
                        help="comma-separated hands to run (default: both)")
    parser.add_argument("--fit", default=None, metavar="KEY=VALUE,...",
                        help="plan with isf.FitConfig(KEY=VALUE, ...) instead of the paper's "
                             "parameters, e.g. finger_damping=1e-6 (a diagnostic for finger QPs "
                             "that fail to converge) or tolerance=0.024")
    parser.add_argument("--repair", default=None, metavar="KEY=VALUE,...",
                        help="plan with isf.RepairConfig(KEY=VALUE, ...) instead of the default "
                             "repair, e.g. max_rows=12,activation=0.008")
    parser.add_argument("--modes", default="w2,1",
                        help="comma-separated modes of isf.plan: a batch size (1: the paper's "
                             "sequential loop) or wN (N worker threads); default w2,1; the last "
                             "is the reference of the speed-up column")
    parser.add_argument("--objects", type=int, default=len(YCB_OBJECTS),
                        help=f"how many of the benchmark objects to run, in order (default "
                             f"{len(YCB_OBJECTS)}; --quick: 1)")
    parser.add_argument("--samples", type=int, default=SAMPLES,
                        help=f"samples per plan (default {SAMPLES}; --quick: {QUICK_SAMPLES})")
    args = parser.parse_args()
    try:
        args.modes = [_common.Mode.parse(m) for m in args.modes.split(",")]
    except ValueError as err:
        parser.error(f"--modes: {err}")
    if args.fit is not None:
        args.fit = _common.parse_config(parser, args.fit, "--fit", isf.FitConfig)
    if args.repair is not None:
        args.repair = _common.parse_config(parser, args.repair, "--repair", isf.RepairConfig)
    if args.quick:
        args.repeats, args.objects = min(args.repeats, 1), 1
        args.samples = min(args.samples, QUICK_SAMPLES)
    started = time.perf_counter()
    header = _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    objects, note = load_objects(args.objects)
    rows = []
    with tempfile.TemporaryDirectory(prefix="isf-bench-allegro-") as folder:
        makers = {"three-finger": lambda: isf.load_gripper("three-finger"),
                  ALLEGRO: lambda: tagged_allegro(Path(folder))}
        wanted = args.hands.split(",")
        unknown = sorted(set(wanted) - set(makers))
        if unknown:
            parser.error(f"unknown hands {unknown}; choose from {sorted(makers)}")
        hands = [(name, makers[name]()) for name in wanted]
        for obj in objects:  # both hands on the first object first (priority under --deadline)
            for hand, gripper in hands:
                for mode in args.modes:
                    if deadline.allows(f"{hand} on {obj.name}, {mode.label}"):
                        rows.append(bench(hand, gripper, obj, mode, args))
                    else:
                        rows.append({"hand": hand, "object": obj.name, "points": obj.n_points,
                                     "mode": mode})
    rows.sort(key=lambda r: [h for h, _ in hands].index(r["hand"]))
    _common.finish("bench_hands: multi-fingered hands", report(rows, note, args, deadline),
                   started, header, args.out)


if __name__ == "__main__":
    main()
