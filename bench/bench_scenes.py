"""Planning on what a depth camera sees: random tabletop scenes judged against their ground truth.

Scenes come from ``bench/scene_sim.py`` (3-8 YCB objects in stable poses, touching neighbours
included, rendered by one or two simulated depth cameras with a realistic sensor model) and every
grasp is judged by ``bench/scene_judge.py`` on the ground-truth meshes and the table, without
isf's collision checker: a grasp passes when it penetrates nothing deeper than 2 mm and its
contact surfaces all touch one and the same object (within 2 mm). docs/benchmark-scenes.md
describes the method and holds the results.

The planner sees only the depth images: ``isf.load_scene([isf.SceneView(depth,
intrinsics=..., T_scene_camera=...), ...], table=<--table>)`` and ``isf.plan(gripper, scene,
samples=60, seed=...)``. A grasp is "returned" when the planner marks it valid (collision-free
with every contact surface touching); the best returned grasp is the top-1, the first five are
the top-5.

Experiments (scene k of ``--scenes`` uses seed ``--seed + k``, 3 + k mod 6 objects, one camera
for even k and two for odd k; both grippers plan on the same rendered images):

1. top-1 and top-5 pass rates on the cluttered scenes (targets: top-1 >= 95 % of scenes,
   top-5 >= 90 % of grasps);
2. sequential picking (the paper's Fig. 8) on the same scenes: take the best grasp and judge it;
   if it passes, remove the grasped object from the ground truth and render again, else count a
   failed attempt and plan again with the next seed; stop when the table is clear, no grasp is
   returned, or after 2 x objects attempts. Reported: objects cleared per attempt and the share
   of objects cleared with at most one failed attempt since the previous pick (target >= 90 %);
3. partial single-object views: one object, one camera 0.6 m away (1 mm noise there), top-5
   pass rate (target >= 95 %);
4. time: the 60-sample plan of every one-camera cluttered scene over the median 60-sample plan
   of its objects loaded complete (``isf.load_object`` of the same meshes), CPU time and wall
   time measured in this process (target <= 3x on the 5-object scenes).

The plans on complete objects also calibrate the judge: their top-5 valid grasps are judged on
the object alone (no table), and the report gives, for every experiment, the median and largest
penetration of the top-5 grasps.

Grippers: the bundled ``flat-parallel`` and the Franka hand (``isf.assets.vendor_gripper
("franka-hand")``) tagged in a temporary copy by ``isf tag`` with its suggestions
(:func:`_common.tagged_franka_hand`: a pad on the distal half of each finger's inner face).

Options: ``--scenes N`` (default 20), ``--partial N`` (default: as many as ``--scenes``),
``--gripper NAME`` (repeatable: ``flat-parallel``, ``franka-hand``; default both), ``--seed S``,
``--table auto|Z``, ``--samples`` (default 60), ``--quick`` (4 scenes, 4 partial views),
``--deadline`` seconds, ``--out FILE`` (the markdown report).

The YCB meshes are needed (``../shared/data/ycb`` or ``$ISF_YCB_DIR``); without them the script
says so and exits.

Run from the repository root:
    python bench/bench_scenes.py [--quick] [--scenes 20] [--gripper franka-hand] [--out FILE]
"""

from __future__ import annotations

import _common

import statistics
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import isf
from isf import assets

import scene_judge
import scene_sim

SAMPLES = 60
TOP = 5
GRIPPERS = ("flat-parallel", "franka-hand")
TARGETS = {"top1": 0.95, "top5": 0.90, "picking": 0.90, "partial": 0.95, "time_ratio": 3.0}
#: A penetrated surface point is seen when a camera measured it within this depth, metres.
SEEN_TOLERANCE = 0.005
PARTIAL_DISTANCE = 0.6  # m, camera to object in the partial views: the sensor's 1 mm there


# --------------------------------------------------------------------------- grippers


def load_grippers(names: list[str], folder: Path) -> dict[str, isf.Gripper]:
    return {n: _common.tagged_franka_hand(folder) if n == "franka-hand" else isf.load_gripper(n)
            for n in names}


# --------------------------------------------------------------------------- one plan


@dataclass
class Rendered:
    """Depth views of a ground-truth scene and what the planner made of them."""

    truth: scene_sim.Scene
    views: list[scene_sim.DepthView]
    scene: object | None  # isf's scene, None when load_scene refused the images
    load_time: float
    error: str = ""

    @property
    def observed(self) -> int:
        return sum(v.n_points for v in self.views)


def render(truth: scene_sim.Scene, cameras: list[scene_sim.Camera], seed: int, table
           ) -> Rendered:
    """Render ``truth`` from ``cameras`` and load the depth images with ``isf.load_scene``."""
    views = [scene_sim.render(truth, c, rng=seed * 10 + k) for k, c in enumerate(cameras)]
    isf_views = []
    for v in views:
        i = v.camera.intrinsics
        intrinsics = isf.CameraIntrinsics(fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, width=i.width,
                                          height=i.height)
        isf_views.append(isf.SceneView(v.depth, intrinsics=intrinsics,
                                       T_scene_camera=v.camera.T_scene_camera))
    t0 = time.perf_counter()
    try:
        scene = isf.load_scene(isf_views, table=table)
    except isf.ISFError as err:
        return Rendered(truth, views, None, time.perf_counter() - t0, str(err))
    return Rendered(truth, views, scene, time.perf_counter() - t0)


@dataclass
class Planned:
    """One plan on a rendered scene and the judge's verdicts on its top grasps."""

    returned: int  # grasps the planner marked valid
    verdicts: list[scene_judge.Judgement]  # of the first TOP returned grasps, best first
    wall: float  # PlanStats.total_time, s
    cpu: float  # process time around isf.plan, s
    error: str = ""  # what isf.plan raised, if it raised

    @property
    def top1(self) -> scene_judge.Judgement | None:
        return self.verdicts[0] if self.verdicts else None


PLAN_OPTIONS: dict = {}
"""Keyword arguments of every ``isf.plan`` on a scene (``--tolerance``)."""


def plan_and_judge(gripper, rendered: Rendered, seed: int, samples: int,
                   top: int = TOP) -> Planned:
    if rendered.scene is None:
        return Planned(0, [], 0.0, 0.0)
    c0 = time.process_time()
    try:
        result = isf.plan(gripper, rendered.scene, samples=samples, seed=seed, **PLAN_OPTIONS)
    except Exception as err:  # a long run records a planner failure and goes on
        print(f"# isf.plan raised on scene {rendered.truth.seed}: {type(err).__name__}: {err}",
              flush=True)
        return Planned(0, [], 0.0, 0.0, f"{type(err).__name__}: {err}")
    cpu = time.process_time() - c0
    free = [g for g in result.grasps if g.valid]
    judge = scene_judge.Judge(gripper, rendered.truth)
    verdicts = [judge(g.T_object_gripper, g.q) for g in free[:top]]
    return Planned(len(free), verdicts, result.stats.total_time, cpu)


def failure_kind(verdict: scene_judge.Judgement | None, rendered: Rendered | None, gripper,
                 planned: Planned | None = None) -> str:
    """A failed grasp's category: penetration by a finger (a link with a contact surface) or
    another link (the palm) into a seen or an unseen surface, the table, no contact, two objects,
    or no grasp returned."""
    if verdict is None:
        if planned is not None and planned.error:
            return "isf.plan raised"
        return "no grasp returned" if rendered.scene is not None else "load_scene refused"
    if verdict.passed:
        return "passed"
    if verdict.reason == "penetration":
        seen = rendered is None or any(v.sees(verdict.deepest_point, SEEN_TOLERANCE)
                                       for v in rendered.views)
        side = "a seen" if seen else "an unseen"
        part = "a finger" if verdict.link in gripper.contact_links else "the palm"
        return f"penetration by {part} into {side} surface"
    return {"table": "penetration (table)", "no contact": "a surface touches nothing",
            "two objects": "contacts on two objects"}[verdict.reason]


# --------------------------------------------------------------------------- experiments


@dataclass
class SceneRecord:
    """Experiments 1, 2 and 4 on one scene, for one gripper."""

    seed: int
    n_objects: int
    cameras: int
    observed: int
    first: Planned
    attempts: int = 0
    cleared: int = 0
    cleared_promptly: int = 0  # cleared with at most one failed attempt since the last pick
    stop: str = ""
    failures: list[str] = field(default_factory=list)  # notes on failed picks
    rendered: Rendered | None = None  # the first rendering


def pick_sequence(gripper, truth: scene_sim.Scene, cameras, first_render: Rendered,
                  first: Planned, seed: int, samples: int, table, record: SceneRecord) -> None:
    """Experiment 2: pick until the table is clear, nothing is returned or 2 x objects attempts."""
    rendered, planned, plan_seed = first_render, first, seed
    failed_since_pick = 0
    limit = 2 * len(truth.objects)
    while True:
        verdict = planned.top1
        if verdict is None:
            record.stop = failure_kind(None, rendered, gripper, planned)
            if rendered.error or planned.error:
                record.stop += f": {rendered.error or planned.error}"
            return
        record.attempts += 1
        if verdict.passed:
            record.cleared += 1
            record.cleared_promptly += failed_since_pick <= 1
            failed_since_pick = 0
            truth = truth.without(verdict.grasped)
        else:
            failed_since_pick += 1
            record.failures.append(f"attempt {record.attempts}: {failure_kind(verdict, rendered, gripper)}"
                                   f" ({verdict.describe()})")
        if not truth.objects:
            record.stop = "table clear"
            return
        if record.attempts >= limit:
            record.stop = f"{limit} attempts"
            return
        plan_seed += 1000
        rendered = render(truth, cameras, plan_seed, table)
        planned = plan_and_judge(gripper, rendered, plan_seed, samples, top=1)


@dataclass
class CompletePlan:
    """A plan on one object loaded complete (no camera, no table): the reference of experiment 4
    and of the judge (its top grasps judged on the same mesh, in the object frame)."""

    cpu: float  # s
    wall: float  # PlanStats.total_time, s
    verdicts: list[scene_judge.Judgement]


def complete_object_plans(gripper, objects: list[scene_sim.CatalogueObject], samples: int,
                          seed: int) -> dict[str, CompletePlan]:
    """A ``samples``-sample plan on each object loaded complete (``isf.load_object`` of its
    mesh file), its top-5 valid grasps judged on the object alone (no table)."""
    out = {}
    for item in objects:
        asset = assets.benchmark_object(item.name)
        obj = isf.load_object(asset.path, scale=asset.scale, name=item.name)
        c0 = time.process_time()
        result = isf.plan(gripper, obj, samples=samples, seed=seed)
        cpu = time.process_time() - c0
        alone = scene_sim.Scene((scene_sim.SceneObject(item.name, item.mesh, np.eye(4)),),
                                table_height=-np.inf)
        judge = scene_judge.Judge(gripper, alone)
        verdicts = [judge(g.T_object_gripper, g.q) for g in result.grasps if g.valid][:TOP]
        out[item.name] = CompletePlan(cpu, result.stats.total_time, verdicts)
    return out


# --------------------------------------------------------------------------- report


def share(passed: int, total: int) -> str:
    return f"{passed}/{total} = {100 * passed / total:.0f} %" if total else "-"


def med_worst(values: list[float], worst=min, digits: int = 2, percent: bool = True) -> str:
    if not values:
        return "-"
    scale, unit = (100, " %") if percent else (1, "")
    return (f"{_common.fmt(statistics.median(values) * scale, digits)}{unit} "
            f"(worst {_common.fmt(worst(values) * scale, digits)}{unit})")


def meets(value: float, target: float, higher_is_better: bool = True) -> str:
    if value != value:
        return "-"
    return "yes" if (value >= target if higher_is_better else value <= target) else "no"


def summary_rows(name: str, records: list[SceneRecord], partial: list[Planned],
                 ratios: list[tuple[int, float, float]], complete: dict[str, CompletePlan]
                 ) -> list[list[str]]:
    top1 = [r.first.top1 is not None and r.first.top1.passed for r in records]
    top5 = [v.passed for r in records for v in r.first.verdicts]
    top5_scene = [np.mean([v.passed for v in r.first.verdicts]) for r in records
                  if r.first.verdicts]
    promptly = sum(r.cleared_promptly for r in records)
    objects = sum(r.n_objects for r in records)
    picking_scene = [r.cleared_promptly / r.n_objects for r in records]
    attempts = sum(r.attempts for r in records)
    partial5 = [v.passed for p in partial for v in p.verdicts]
    partial_scene = [np.mean([v.passed for v in p.verdicts]) for p in partial if p.verdicts]
    five = [cpu for n, cpu, _ in ratios if n == 5]
    reference = [v.passed for plan in complete.values() for v in plan.verdicts]
    depth_clutter = [v.penetration * 1e3 for r in records for v in r.first.verdicts]
    depth_partial = [v.penetration * 1e3 for p in partial for v in p.verdicts]
    depth_complete = [v.penetration * 1e3 for c in complete.values() for v in c.verdicts]
    rows = [
        ["top-1 grasp passes (scenes)", share(sum(top1), len(top1)), ">= 95 %",
         meets(np.mean(top1) if top1 else float("nan"), TARGETS["top1"])],
        ["top-5 grasps passing (grasps)", share(sum(top5), len(top5)), ">= 90 %",
         meets(np.mean(top5) if top5 else float("nan"), TARGETS["top5"])],
        ["top-5 passing per scene, median (worst)", med_worst(top5_scene), "", ""],
        ["valid grasps returned of 60, median (min)",
         med_worst([r.first.returned for r in records], digits=3, percent=False), "", ""],
        ["picking: objects cleared / attempts",
         f"{sum(r.cleared for r in records)} / {attempts}"
         + (f" = {sum(r.cleared for r in records) / attempts:.2f}" if attempts else ""), "", ""],
        ["picking: objects cleared with <= 1 failed attempt", share(promptly, objects),
         ">= 90 %", meets(promptly / objects if objects else float("nan"), TARGETS["picking"])],
        ["picking: that share per scene, median (worst)", med_worst(picking_scene), "", ""],
        ["partial views: top-5 grasps passing", share(sum(partial5), len(partial5)), ">= 95 %",
         meets(np.mean(partial5) if partial5 else float("nan"), TARGETS["partial"])],
        ["partial views: per view, median (worst)", med_worst(partial_scene), "", ""],
        ["complete objects, no camera (reference): top-5 grasps passing",
         share(sum(reference), len(reference)), "", ""],
        ["deepest penetration of the top-5 grasps, mm, median (max): clutter",
         med_worst(depth_clutter, worst=max, percent=False), "", ""],
        ["the same: partial views", med_worst(depth_partial, worst=max, percent=False), "", ""],
        ["the same: complete objects", med_worst(depth_complete, worst=max, percent=False), "",
         ""],
        ["time: scene / complete object, CPU, 5-object scenes, median (worst)",
         med_worst(five, worst=max, percent=False), "<= 3x",
         meets(statistics.median(five) if five else float("nan"), TARGETS["time_ratio"],
               higher_is_better=False)],
        ["time: the same over every one-camera scene, CPU",
         med_worst([cpu for _, cpu, _ in ratios], worst=max, percent=False), "", ""],
        ["time: the same over every one-camera scene, wall",
         med_worst([wall for _, _, wall in ratios], worst=max, percent=False), "", ""],
    ]
    return [[name, *row] for row in rows]


def failure_table(name: str, gripper, records: list[SceneRecord],
                  partial: list[tuple[Rendered, Planned]], complete: dict[str, CompletePlan]
                  ) -> list[list[str]]:
    rows = []
    for label, triples in (
        ("top-5 (complete objects)", [(None, v, None) for c in complete.values()
                                      for v in c.verdicts]),
        ("top-5 (clutter)", [(r.rendered, v, r.first) for r in records for v in r.first.verdicts]),
        ("top-1 (clutter)", [(r.rendered, r.first.top1, r.first) for r in records]),
        ("top-5 (partial)", [(rd, v, p) for rd, p in partial for v in p.verdicts]),
        ("top-1 (partial)", [(rd, p.top1, p) for rd, p in partial]),
    ):
        kinds = Counter(failure_kind(v, rd, gripper, p) for rd, v, p in triples
                        if v is None or not v.passed)
        rows.append([name, label, ", ".join(f"{k}: {n}" for k, n in kinds.most_common()) or
                     "none"])
    return rows


# --------------------------------------------------------------------------- main


def parse_args():
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0)
    parser.add_argument("--scenes", type=int, default=20, help="cluttered scenes (default 20)")
    parser.add_argument("--partial", type=int, default=None,
                        help="partial single-object views (default: as many as --scenes)")
    parser.add_argument("--gripper", action="append", choices=GRIPPERS,
                        help="a gripper to run (repeatable; default both)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first scene")
    parser.add_argument("--table", default="auto", help="'auto' or the table height z (m)")
    parser.add_argument("--samples", type=int, default=SAMPLES, help="samples per plan")
    parser.add_argument("--tolerance", type=float, default=None,
                        help="the planner's collision tolerance on scenes, m (default isf.plan's)")
    parser.set_defaults(deadline=0)
    args = parser.parse_args()
    if args.quick:
        args.scenes = min(args.scenes, 4)
        args.partial = min(args.partial or 4, 4)
    if args.partial is None:
        args.partial = args.scenes
    args.table = args.table if args.table == "auto" else float(args.table)
    args.gripper = args.gripper or list(GRIPPERS)
    return args


def main() -> None:
    args = parse_args()
    if args.tolerance is not None:
        PLAN_OPTIONS["collision_tolerance"] = args.tolerance
    started = time.perf_counter()
    try:
        objects = scene_sim.catalogue()
    except assets.YCBNotFoundError as err:
        print(f"# skipped: the scene benchmark needs the YCB meshes ({err})")
        sys.exit(0)
    if not hasattr(isf, "load_scene"):
        sys.exit("this isf has no isf.load_scene: the scene benchmark needs the scene planner")
    header = _common.machine_description()
    with tempfile.TemporaryDirectory() as tmp:  # the tagged Franka copy lives here
        sections = run(args, objects, load_grippers(args.gripper, Path(tmp)))
    _common.finish("Scene benchmark: plans on simulated depth images, judged on the ground "
                   "truth", sections, started, header, args.out)


def run(args, objects: list[scene_sim.CatalogueObject], grippers: dict[str, isf.Gripper]
        ) -> list[str]:
    """Every experiment for every gripper; returns the report's sections."""
    deadline = _common.Deadline(args.deadline)
    records = {n: [] for n in grippers}
    partial = {n: [] for n in grippers}
    names = [o.name for o in objects]
    object_times = {n: complete_object_plans(g, objects, args.samples, args.seed)
                    for n, g in grippers.items()}
    ratios = {n: [] for n in grippers}

    for k in range(max(args.scenes, args.partial)):  # interleaved, so a deadline cuts both
        if k < args.scenes:
            seed = args.seed + k
            n_objects, n_cameras = 3 + k % 6, 1 + k % 2
            if not deadline.allows(f"scene {seed}"):
                break  # the deadline passed
            truth = scene_sim.random_scene(objects, n_objects, seed)
            cameras = scene_sim.random_cameras(np.random.default_rng(seed), n_cameras)
            rendered = render(truth, cameras, seed, args.table)
            for name, gripper in grippers.items():
                first = plan_and_judge(gripper, rendered, seed, args.samples)
                record = SceneRecord(seed, len(truth.objects), n_cameras, rendered.observed, first,
                                     rendered=rendered)
                pick_sequence(gripper, truth, cameras, rendered, first, seed, args.samples,
                              args.table, record)
                records[name].append(record)
                if n_cameras == 1 and first.cpu > 0:
                    ref = [object_times[name][o].cpu for o in truth.names]
                    ref_wall = [object_times[name][o].wall for o in truth.names]
                    ratios[name].append((len(truth.objects), first.cpu / statistics.median(ref),
                                         first.wall / statistics.median(ref_wall)))
                top = (first.top1.describe() if first.top1
                       else failure_kind(None, rendered, gripper, first))
                print(f"# scene {seed} ({len(truth.objects)} objects, {n_cameras} camera(s), "
                      f"{rendered.observed} points) {name}: {first.returned} returned, "
                      f"{sum(v.passed for v in first.verdicts)}/{len(first.verdicts)} of the top "
                      f"pass, plan {first.cpu:.1f} s CPU; top-1 {top}; picking: {record.cleared}/"
                      f"{record.n_objects} cleared in {record.attempts} attempts ({record.stop})",
                      flush=True)
        if k < args.partial:
            seed = args.seed + 1000 + k
            if not deadline.allows(f"partial view {seed}"):
                break
            truth = scene_sim.random_scene(objects, 1, seed)
            cameras = scene_sim.random_cameras(np.random.default_rng(seed), 1,
                                               distance=(PARTIAL_DISTANCE, PARTIAL_DISTANCE),
                                               target=truth.objects[0].T_scene_object[:3, 3])
            rendered = render(truth, cameras, seed, args.table)
            for name, gripper in grippers.items():
                planned = plan_and_judge(gripper, rendered, seed, args.samples)
                partial[name].append((rendered, planned))
                print(f"# partial view {seed} ({truth.names[0]}, {rendered.observed} points) "
                      f"{name}: {planned.returned} returned, {sum(v.passed for v in planned.verdicts)}/"
                      f"{len(planned.verdicts)} of the top pass", flush=True)

    summary, failures, notes = [], [], []
    for name in grippers:
        summary += summary_rows(name, records[name], [p for _, p in partial[name]],
                                ratios[name], object_times[name])
        failures += failure_table(name, grippers[name], records[name], partial[name],
                                  object_times[name])
        for r in records[name]:
            for note in r.failures:
                notes.append(f"- {name}, scene {r.seed} ({r.n_objects} objects, {r.cameras} "
                             f"camera(s)): {note}")
    first = next(iter(grippers))
    return [
        f"{len(records[first])} cluttered scenes (seeds {args.seed}..), {len(partial[first])} "
        f"partial views (seeds {args.seed + 1000}..), {args.samples} samples per plan, table "
        f"{args.table!r}; objects: {', '.join(names)}.",
        _common.markdown_table(["gripper", "measure", "value", "target", "met"], summary),
        "Failed grasps by kind (a penetration is into a seen surface when a camera measured the "
        "ground-truth surface point nearest to its deepest point, within "
        f"{SEEN_TOLERANCE * 1e3:.0f} mm of depth in a 3 x 3 pixel block; a finger is a link "
        "carrying a contact surface, the palm any other link):",
        _common.markdown_table(["gripper", "grasps", "failures"], failures),
        "Failed picking attempts:\n\n" + ("\n".join(notes) if notes else "none"),
        *deadline.note(),
    ]


if __name__ == "__main__":
    main()
