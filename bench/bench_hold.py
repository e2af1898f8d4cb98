"""Do isf's best grasps hold? The physics test of ``isf validate`` on the ten YCB objects.

For each gripper and YCB object (real size, ``asset:ycb:NAME``; ``--objects held-out``: nine
objects nothing in isf was tuned on, :data:`HELD_OUT`), one ``isf.plan`` of 60 samples
(regret sampler, seed 0) per ranking, and the top 5 grasps simulated by
:func:`isf.simulation.validate_grasp` (friction 0.5, 0.3 kg, 20 N from each contact surface: the
defaults of ``isf validate``; ``--finger-force``, ``--friction`` and ``--mass`` set others, and
the plans' quality ranking is given the same friction and mass; docs/validate.md). A grasp
*holds* when the object stays within 10 mm and 0.2 rad of its closed pose with gravity along
each of +-x, +-y, +-z. Reported per gripper and ranking: top-1 = % of objects whose best
grasp holds in all six directions; top-5 = % of the top-5 grasps (over all objects) that hold
in all six; and the outcomes by kind.

Rankings: ``fit`` (the paper's: valid first, then the fitting error) and, when ``isf.plan``
has a ``rank`` parameter, ``quality`` (its stability-aware default). When
``bench/antipodal_baseline.py`` is present, its ``plan_antipodal`` (friction-cone contact
pairs, ranked by normal alignment and distance from the centre of mass, collision-checked) is
judged the same way, for the parallel grippers and the Franka hand.

Grippers: ``paper-parallel``, ``flat-parallel``, ``three-finger`` (bundled), ``franka-hand``
(the vendor hand tagged by ``isf tag``'s suggestions, :func:`_common.tagged_franka_hand`),
``allegro-right`` (the vendor Allegro hand with one contact cap per fingertip, as
bench/bench_hands.py tags it, which is not what ``isf tag`` suggests: docs/validate.md;
no ``<isf:closing>`` tags, so each joint closes the way its
contact surfaces' outward normals point, ``Gripper.suggested_closing``), ``allegro-suggested``
(the same vendor hand tagged as a user would tag it: ``isf tag URDF --palm-link palm_link``,
every suggestion taken: fingertip pads facing the other fingertips, approach, tool-centre
point and ``<isf:closing>`` signs: the flexion joints close, the abduction joints hold),
``robotiq-2f-85`` (the vendor Robotiq 2F-85 tagged by ``isf tag`` with every suggestion: a
gripper nothing in isf was tuned on) and ``paper-parallel-scaled``: ``paper-parallel`` (2.3 cm
opening, which no YCB object fits at real size) on each object scaled uniformly so that its
smallest principal width is ``SCALED_FILL`` of the opening (the same 0.3 kg: only the geometry
is scaled).

``--seed N`` plans with another seed (default 0). ``--com-share S`` plans with
``RegretSampler(com_share=S)``: ``0`` starts every sample at a cluster centre (the paper's
Algorithm 3), the default starts every second one at the centre of mass (docs/samplers.md).
``--hear-quality`` plans with ``RegretSampler(hear_quality=True)`` (docs/samplers.md).

With ``--every-valid``, every valid grasp of each ``quality`` plan is simulated too, not only
the top 5: how many of them hold, by distance of their contacts from the centre of mass, how
well the smallest gravity margin separates held from failed grasps (area under the ROC
curve), and the best top-1 and top-5 that any ranking of the plan's grasps could reach.

Run from the repository root:
    python bench/bench_hold.py [--quick] [--grippers paper-parallel,franka-hand]
                               [--objects ycb|held-out|Banana,asset:bottle] [--raw FILE.json]
                               [--out FILE.md]
                               [--every-valid] [--seed N] [--com-share S] [--hear-quality]
                               [--friction MU] [--mass KG] [--finger-force N]
"""

from __future__ import annotations

import _common

import contextlib
import importlib
import importlib.util
import io
import inspect
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf.samplers.regret import RegretSampler
from isf.simulation import SimulationSettings, object_body, validate_grasp

SAMPLES, SEED, TOP = 60, 0, 5
#: what every isf.plan of this script is given besides the gripper and object (set by main):
#: the quality ranking's friction and mass are the judge's (isf validate's defaults unless
#: --friction and --mass say otherwise), and the antipodal baseline gets the same friction
PLAN_OPTIONS: dict = {"samples": SAMPLES, "seed": SEED, "quality": isf.QualityConfig(
    friction=SimulationSettings().friction, mass=SimulationSettings().mass)}


def plan(gripper, obj, **options):
    """``isf.plan`` with :data:`PLAN_OPTIONS` (a fresh sampler each time)."""
    options = {**PLAN_OPTIONS, **options}
    if callable(options.get("sampler")):
        options["sampler"] = options["sampler"]()
    return isf.plan(gripper, obj, **options)
GRIPPERS = ("paper-parallel", "paper-parallel-scaled", "flat-parallel", "three-finger",
            "franka-hand", "allegro-right", "allegro-suggested", "robotiq-2f-85")
PARALLEL = ("paper-parallel", "paper-parallel-scaled", "flat-parallel", "franka-hand",
            "robotiq-2f-85")
SCALED = "-scaled"
SCALED_FILL = 0.6
OBJECTS = ("Banana", "CrackerBox", "FoamBrick", "GelatinBox", "MasterChefCan", "MustardBottle",
           "PottedMeatCan", "PowerDrill", "Scissors", "TomatoSoupCan")
#: objects no ranking, centring or sampler default was tuned on (``--objects held-out``): the
#: robosuite household meshes at real size, the pybullet duck and mug, and one of pybullet's
#: procedural random objects (isf.assets; on the next, random-403, CoACD ran more than eight
#: CPU-minutes at the simulation's 1 mm tolerance without finishing)
HELD_OUT = ("asset:bottle", "asset:bread", "asset:can", "asset:cereal", "asset:lemon",
            "asset:milk", "asset:duck", "asset:mug", "asset:random-402")
#: (top-1, top-5) of the hands; the parallel grippers and the Franka hand: (0.95, 0.90)
TARGETS = {"three-finger": (0.90, 0.80), "allegro-right": (0.90, 0.80),
           "allegro-suggested": (0.90, 0.80)}


def object_spec(name: str) -> str:
    """The ``isf.open_object`` spec of an ``--objects`` entry: a YCB name or a spec."""
    return name if ":" in name else f"asset:ycb:{name}"


def object_names(option: str) -> list[str]:
    """The entries of ``--objects``: ``ycb``, ``held-out`` or a comma-separated list."""
    return list({"ycb": OBJECTS, "held-out": HELD_OUT}.get(option, option.split(",")))


def meets(value: float, target: float) -> str:
    """``"yes"`` when the fraction ``value`` reaches ``target``, else ``"no (target N %)"``."""
    return "yes" if value >= target else f"no (target {100 * target:.0f} %)"


def load(name: str, folder: Path) -> isf.Gripper:
    name = name.removesuffix(SCALED)
    if name == "franka-hand":
        return _common.tagged_franka_hand(folder)
    if name == "allegro-right":
        import bench_hands

        return bench_hands.tagged_allegro(folder)
    if name == "allegro-suggested":
        return suggested_allegro(folder)
    if name == "robotiq-2f-85":
        return suggested_robotiq(folder)
    return isf.load_gripper(name)


def suggested_robotiq(folder: Path) -> isf.Gripper:
    """The vendor Robotiq 2F-85 (``isf.assets.vendor_gripper("robotiq-2f-85")``) tagged by
    ``isf tag`` with every suggestion and nothing named, written into ``folder`` and loaded."""
    from isf import assets

    return tagged_by_isf_tag(Path(assets.vendor_gripper("robotiq-2f-85")),
                             folder / "robotiq_2f_85.urdf")


def suggested_allegro(folder: Path) -> isf.Gripper:
    """The vendor Allegro hand tagged by ``isf tag`` with its suggestions (only the palm link
    named), written into ``folder`` and loaded."""
    import bench_hands
    from isf import assets

    source = Path(assets.vendor_gripper(bench_hands.ALLEGRO))
    args = ("--palm-link", bench_hands.ALLEGRO_PALM)
    for package, path in bench_hands._package_dirs(source, source.read_text()).items():
        args += ("--package", f"{package}={path}")
    return tagged_by_isf_tag(source, folder / "allegro_suggested.urdf", args)


def tagged_by_isf_tag(source: Path, out: Path, args: tuple[str, ...] = ()) -> isf.Gripper:
    """``isf tag SOURCE --out OUT ARGS`` (every suggestion taken), then the copy loaded."""
    from isf.cli import main

    with contextlib.redirect_stdout(io.StringIO()):  # isf tag's preview of what it selected
        status = main(["tag", str(source), "--out", str(out), *args])
    if status != 0:
        raise SystemExit(f"isf tag failed on {source}")
    return isf.load_gripper(out)


def scaled_object(gripper: isf.Gripper, spec: str):
    """The object of ``spec`` scaled so that its smallest principal width is ``SCALED_FILL`` of
    the gripper's largest opening (never enlarged), and the scale."""
    from isf.planning.span import gripper_span, object_extent

    scale = min(1.0, SCALED_FILL * gripper_span(gripper).largest
                / object_extent(isf.open_object(spec)).smallest)
    return isf.open_object(spec, scale=scale), scale


def rankings() -> tuple[str, ...]:
    return ("fit", "quality") if "rank" in inspect.signature(isf.plan).parameters else ("fit",)


def baseline():
    """``plan_antipodal`` of bench/antipodal_baseline.py, or None when absent."""
    if importlib.util.find_spec("antipodal_baseline") is None:
        return None
    return getattr(importlib.import_module("antipodal_baseline"), "plan_antipodal", None)


def candidates(method: str, gripper, obj, plan_antipodal) -> list[tuple[np.ndarray, np.ndarray]]:
    """The top grasps of one method as (T_object_gripper (4, 4), q (n_joints,)) pairs."""
    if method == "antipodal":
        grasps = plan_antipodal(gripper, obj, n_grasps=20, seed=PLAN_OPTIONS["seed"],
                                friction=PLAN_OPTIONS["quality"].friction)
    elif method == "fit" and len(rankings()) == 1:
        grasps = plan(gripper, obj).grasps
    else:
        grasps = plan(gripper, obj, rank=method).grasps
    out = []
    for g in list(grasps)[:TOP]:
        q = getattr(g, "q", None)
        if q is None:
            q = g.fit.q if hasattr(g, "fit") else [g.joints[n] for n in gripper.joint_names]
        out.append((np.asarray(g.T_object_gripper, dtype=float), np.asarray(q, dtype=float)))
    return out


#: Bands of the distance from the contacts' centroid to the centre of mass, metres.
COM_BANDS = (0.0, 0.01, 0.02, 0.03, np.inf)


def every_valid(gripper, obj, body, settings) -> dict:
    """Every valid grasp of one ``quality`` plan simulated: their outcomes, distances from the
    centre of mass (m), smallest gravity margins and squeeze imbalances, in the plan's order."""
    grasps = [g for g in plan(gripper, obj).grasps if g.valid]
    return {"outcomes": [validate_grasp(gripper, body, g.T_object_gripper, g.q, settings)
                         .outcome.value for g in grasps],
            "com_offsets": [g.quality.com_offset for g in grasps],
            "margins": [g.quality.min_margin for g in grasps],
            "squeeze_imbalances": [g.quality.squeeze_imbalance for g in grasps]}


def roc_area(scores, positive) -> float:
    """Area under the ROC curve of ``scores`` separating ``positive`` (bools) from the rest:
    the chance that a random positive scores above a random negative (ties count half)."""
    pos = [s for s, p in zip(scores, positive) if p]
    neg = [s for s, p in zip(scores, positive) if not p]
    if not pos or not neg:
        return float("nan")
    return float(np.mean([(a > b) + 0.5 * (a == b) for a in pos for b in neg]))


def every_valid_report(rows: list[dict]) -> list[str]:
    """The ``--every-valid`` section: per gripper, what the simulated valid grasps say."""
    lines = []
    for name in dict.fromkeys(r["gripper"] for r in rows):
        mine = [r for r in rows if r["gripper"] == name]
        held = [o == "held" for r in mine for o in r["outcomes"]]
        offsets = np.array([c for r in mine for c in r["com_offsets"]])
        margins = [m for r in mine for m in r["margins"]]
        held_of = [sum(o == "held" for o in r["outcomes"]) for r in mine]
        objects = ", ".join(f"{r['object']} {h}/{len(r['outcomes'])}" for r, h in zip(mine, held_of))
        bands = []
        for lo, hi in zip(COM_BANDS, COM_BANDS[1:]):
            inside = (offsets >= lo) & (offsets < hi)
            label = f"{1e3 * lo:.0f}-{1e3 * hi:.0f} mm" if np.isfinite(hi) else f"from {1e3 * lo:.0f} mm"
            bands.append(f"{label}: {int(np.sum(inside & np.array(held, bool)))}/{int(inside.sum())}")
        best1 = sum(h > 0 for h in held_of)
        best5 = sum(min(TOP, h) for h in held_of)
        lines.append(
            f"* `{name}`: {sum(held)} of {len(held)} valid grasps held in all six directions "
            f"({objects}); by distance of the contacts from the centre of mass: "
            f"{', '.join(bands)}. Area under the ROC curve of the smallest margin "
            f"{roc_area(margins, held):.2f}, of the distance (nearer first) "
            f"{roc_area(list(-offsets), held):.2f}. The best any ranking of these plans could "
            f"reach: top-1 {best1}/{len(mine)}, top-5 {best5}/{TOP * len(mine)}."
            + squeeze_report(mine))
    return lines


def squeeze_report(rows: list[dict]) -> str:
    """What the squeeze imbalance says of one gripper's simulated valid grasps (rows with
    ``squeeze_imbalances``; an empty string for raw files written without them)."""
    if not all("squeeze_imbalances" in r for r in rows):
        return ""
    outcomes = _not_penetrating(rows, "outcomes")
    friction = rows[0]["friction"] if rows else 0.0
    balanced = [p <= friction for p in _not_penetrating(rows, "squeeze_imbalances")]

    def count(is_balanced: bool, outcome: str) -> int:
        return sum(b == is_balanced and o == outcome for b, o in zip(balanced, outcomes))

    return (f" Of those not flagged penetrating, the squeeze imbalance (lower first) separates the "
            f"ones not ejected and the held ones with areas under the ROC curve of "
            f"{_roc_pair(rows, 'squeeze_imbalances', outcomes, -1.0)} "
            f"(the smallest margin: {_roc_pair(rows, 'margins', outcomes, 1.0)}, the distance "
            f"from the centre of mass, nearer first: {_roc_pair(rows, 'com_offsets', outcomes, -1.0)}); "
            f"of the {sum(balanced)} balanced (imbalance <= friction {friction}) "
            f"{count(True, 'ejected')} were ejected and {count(True, 'held')} held, of the "
            f"{len(balanced) - sum(balanced)} others {count(False, 'ejected')} and "
            f"{count(False, 'held')}.")


def _not_penetrating(rows: list[dict], key: str) -> list:
    """The values of ``key`` of the grasps not flagged penetrating, in order, over ``rows``."""
    return [v for r in rows for o, v in zip(r["outcomes"], r[key]) if o != "penetrating"]


def _roc_pair(rows: list[dict], key: str, outcomes: list[str], sign: float) -> str:
    """The areas under the ROC curve of ``sign`` times ``key`` separating the not ejected and
    the held grasps (``outcomes``, penetrating ones left out) from the rest: "a and b"."""
    scores = [sign * v for v in _not_penetrating(rows, key)]
    return (f"{roc_area(scores, [o != 'ejected' for o in outcomes]):.2f} and "
            f"{roc_area(scores, [o == 'held' for o in outcomes]):.2f}")


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("--grippers", default=",".join(GRIPPERS), help=f"comma-separated, of {GRIPPERS}")
    parser.add_argument("--objects", default="ycb",
                        help="ycb (the ten YCB objects), held-out (objects nothing was tuned on: "
                        "HELD_OUT) or comma-separated YCB names and object specs (asset:bottle)")
    parser.add_argument("--raw", default=None, help="also write every grasp's outcome as JSON")
    parser.add_argument("--from-raw", default=None, metavar="FILE.json[,FILE.json]",
                        help="report the outcomes previous --raw runs wrote, simulating nothing")
    parser.add_argument("--methods", default=None,
                        help="comma-separated, of fit, quality, antipodal (default: all available)")
    parser.add_argument("--every-valid", action="store_true",
                        help="also simulate every valid grasp of each quality plan")
    parser.add_argument("--seed", type=int, default=SEED, help="seed of every plan")
    parser.add_argument("--no-centring", action="store_true",
                        help="plan with centring=False: grasps where ISF and the repair left them")
    parser.add_argument("--com-share", type=float, default=None, metavar="S",
                        help="plan with RegretSampler(com_share=S) (default: the sampler's own)")
    parser.add_argument("--hear-quality", action="store_true",
                        help="plan with RegretSampler(hear_quality=True): the bandit hears "
                        "whether each valid grasp is expected to hold")
    parser.add_argument("--finger-force", type=float, default=SimulationSettings().finger_force,
                        metavar="N", help="normal force each contact surface can press with, N "
                        "(default: isf validate's)")
    parser.add_argument("--friction", type=float, default=SimulationSettings().friction,
                        help="friction coefficient of the judge, also given to the plans' quality "
                        "ranking and the baseline (default: isf validate's)")
    parser.add_argument("--mass", type=float, default=SimulationSettings().mass, metavar="KG",
                        help="object mass, kg, of the judge and the plans' quality ranking "
                        "(default: isf validate's)")
    parser.set_defaults(deadline=0.0)
    args = parser.parse_args()
    PLAN_OPTIONS["seed"] = args.seed
    PLAN_OPTIONS["quality"] = isf.QualityConfig(friction=args.friction, mass=args.mass)
    if args.no_centring:
        PLAN_OPTIONS["centring"] = False
    if args.com_share is not None or args.hear_quality:
        sampler_options = {"hear_quality": args.hear_quality}
        if args.com_share is not None:
            sampler_options["com_share"] = args.com_share
        PLAN_OPTIONS["sampler"] = lambda: RegretSampler(**sampler_options)
    grippers = args.grippers.split(",")
    objects = object_names(args.objects)[:2] if args.quick else object_names(args.objects)
    started, header = time.perf_counter(), _common.machine_description()
    deadline = _common.Deadline(args.deadline)
    settings = SimulationSettings(friction=args.friction, mass=args.mass,
                                  finger_force=args.finger_force)
    plan_antipodal = baseline()
    rows: list[dict] = ([r for f in args.from_raw.split(",") for r in json.loads(Path(f).read_text())]
                        if args.from_raw else [])
    with tempfile.TemporaryDirectory(prefix="isf-bench-hold-") as folder:
        loaded = {} if args.from_raw else {name: load(name, Path(folder)) for name in grippers}
        for obj_name in [] if args.from_raw else objects:
            real = isf.open_object(object_spec(obj_name))
            real_body = object_body(real.mesh_vertices, real.mesh_faces, settings.mass)
            for name, gripper in loaded.items():
                obj, body, scale = real, real_body, 1.0
                if name.endswith(SCALED):
                    obj, scale = scaled_object(gripper, object_spec(obj_name))
                    body = object_body(obj.mesh_vertices, obj.mesh_faces, settings.mass)
                methods = list(rankings())
                if plan_antipodal is not None and name in PARALLEL:
                    methods.append("antipodal")
                if args.methods:
                    methods = [m for m in methods if m in args.methods.split(",")]
                for method in methods:
                    label = f"{name} / {method} on {obj_name}"
                    if not deadline.allows(label):
                        continue
                    t0 = time.perf_counter()
                    outcomes = [validate_grasp(gripper, body, T, q, settings)
                                for T, q in candidates(method, gripper, obj, plan_antipodal)]
                    rows.append({"gripper": name, "method": method, "object": obj_name,
                                 "scale": scale, "friction": settings.friction,
                                 "mass": settings.mass,
                                 "outcomes": [v.outcome.value for v in outcomes],
                                 "held_directions": [v.held_directions for v in outcomes],
                                 "seconds": time.perf_counter() - t0})
                    print(f"# {label}: {' '.join(rows[-1]['outcomes'])} "
                          f"({rows[-1]['seconds']:.0f} s)", flush=True)
                    if args.every_valid and method == "quality":
                        rows[-1]["every_valid"] = every_valid(gripper, obj, body, settings)
                    if args.raw:
                        Path(args.raw).write_text(json.dumps(rows, indent=1))
    body_rows = []
    for name in dict.fromkeys(r["gripper"] for r in rows):
        top1_target, top5_target = TARGETS.get(name, (0.95, 0.90))
        for method in dict.fromkeys(r["method"] for r in rows if r["gripper"] == name):
            mine = [r for r in rows if r["gripper"] == name and r["method"] == method]
            top1 = sum(bool(r["outcomes"]) and r["outcomes"][0] == "held" for r in mine)
            # a method that found fewer than TOP grasps fails on the missing ones
            all5 = [o for r in mine for o in r["outcomes"] + ["no grasp"] * (TOP - len(r["outcomes"]))]
            held5 = sum(o == "held" for o in all5)
            kinds = ", ".join(f"{k} {sum(o == k for o in all5)}"
                              for k in ("slipped", "ejected", "penetrating", "no grasp") if k in all5)
            body_rows.append([name, method, len(mine),
                              f"{top1}/{len(mine)} ({100 * top1 / max(1, len(mine)):.0f} %)",
                              meets(top1 / max(1, len(mine)), top1_target),
                              f"{held5}/{len(all5)} ({100 * held5 / max(1, len(all5)):.0f} %)",
                              meets(held5 / max(1, len(all5)), top5_target),
                              kinds or "-"])
    table = _common.markdown_table(
        ["gripper", "ranking", "objects", "top-1 holds in all 6", "target top-1",
         "top-5 grasps holding in all 6", "target top-5", "top-5 failures"], body_rows)
    per_object = _common.markdown_table(
        ["gripper", "ranking", "object", "top-5 outcomes (directions held of 6)"],
        [[r["gripper"], r["method"], r["object"],
          " ".join(f"{o[0].upper()}{h}" for o, h in zip(r["outcomes"], r["held_directions"]))]
         for r in rows])
    share = RegretSampler().com_share if args.com_share is None else args.com_share
    sampler = f"regret sampler (com_share {share}{', hearing the quality' if args.hear_quality else ''})"
    sampler += ", grasps not centred" if args.no_centring else ", grasps centred"
    judges = sorted({(r.get("friction", SimulationSettings().friction),
                      r.get("mass", SimulationSettings().mass)) for r in rows})
    judged = " or ".join(f"friction {mu}, {kg} kg" for mu, kg in judges)
    text = (f"{SAMPLES} samples, {sampler}, seed {args.seed}, objects at real size; top {TOP} "
            f"grasps of each plan simulated with {judged}, "
            f"finger force {settings.finger_force} N. Outcome letters: "
            "H held in all six directions, S slipped (in at least one), E ejected while closing, "
            "P penetrating; the digit is how many directions held. A method that returned fewer than "
            f"{TOP} grasps for an object counts each missing one as a failure.")
    valid_rows = [{"gripper": r["gripper"], "object": r["object"],
                   "friction": r.get("friction", SimulationSettings().friction), **r["every_valid"]}
                  for r in rows if "every_valid" in r]
    extra = (["### Every valid grasp of the quality plans", *every_valid_report(valid_rows)]
             if valid_rows else [])
    _common.finish("bench_hold: do the top grasps hold in physics (isf validate)?",
                   ["### Top grasps held", text, table, "### By object", per_object, *extra,
                    *deadline.note()], started, header, args.out)


if __name__ == "__main__":
    main()
