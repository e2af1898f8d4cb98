"""The ``isf`` command line: ``plan``, ``grippers``, ``samplers``, ``tag``, ``inspect``.

Exit codes: 0 success, 1 a gripper with problems (``inspect``, ``tag``) or a
plan that found no collision-free grasp (of any of the objects planned), 2 a usage or input
error (one line on stderr, no traceback, no output file written).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import threading
from pathlib import Path

from . import __version__
from .exceptions import InvalidInputError, ISFError
from .planning.planner import BATCH_SIZE

__all__ = ["main"]

EXIT_OK, EXIT_NOTHING_FOUND, EXIT_USAGE = 0, 1, 2


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="isf", description="Grasp planning for customized grippers by Iterative Surface Fitting."
    )
    parser.add_argument("--version", action="version", version=f"isf {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("plan", help="plan grasps of an object", description=(
        "Plan grasps of OBJECT with GRIPPER and write them as JSON. GRIPPER is a bundled name "
        "(see 'isf grippers') or a tagged URDF; OBJECT is a mesh or point-cloud file, "
        "shape:NAME (cylinder, box, sphere, capsule, torus) or asset:NAME (e.g. asset:bunny). "
        "Several --object plan one after the other in one run, with the same parameters, and "
        "write one JSON each into --out-dir: the run starts up once (loading isf and its "
        "compiled kernels takes seconds, longer than a plan)."))
    p.add_argument("--gripper", "-g", required=True, help="bundled gripper name or URDF path")
    p.add_argument("--object", "-o", required=True, action="append", dest="object_specs",
                   metavar="OBJECT",
                   help="mesh/cloud file, shape:NAME or asset:NAME (repeatable, with --out-dir)")
    p.add_argument("--samples", "-n", type=int, default=60, help="samples to evaluate (default 60)")
    p.add_argument("--sampler", "-s", default="regret", help="sampler name (default regret; see 'isf samplers')")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--batch-size", type=int, default=BATCH_SIZE, metavar="B",
                   help=f"samples fitted at once in lockstep (default {BATCH_SIZE}: the paper's sequential loop)")
    p.add_argument("--workers", "-j", type=int, default=1, metavar="W",
                   help="threads that fit, check and repair samples side by side (default 1); the "
                        "sampler then learns each outcome up to 2W-1 samples late")
    p.add_argument("--fit", action="append", default=[], metavar="KEY=VALUE",
                   help="a parameter of ISF (isf.FitConfig), e.g. tolerance=0.016 (repeatable; "
                        "the defaults are the paper's; docs/concepts.md lists them, and what a "
                        "looser stop rule saves and costs)")
    p.add_argument("--repair", action="append", default=[], metavar="KEY=VALUE",
                   help="a parameter of the collision repair (isf.RepairConfig), e.g. iterations=10 "
                        "(repeatable; docs/hands.md measures its rows)")
    p.add_argument("--no-repair", action="store_true",
                   help="keep colliding fits as they are (the paper's Algorithm 3)")
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="units of the object file (default m)")
    p.add_argument("--scale", type=float, default=1.0, help="extra scale factor for the object")
    p.add_argument("--table", type=float, default=None, metavar="Z",
                   help="a table plane at height Z (object frame, metres): grasps below it are rejected")
    p.add_argument("--top", type=int, default=None, metavar="K", help="keep only the best K grasps in the output")
    p.add_argument("--out", default=None,
                   help="output JSON file of one object (default grasps.json)")
    p.add_argument("--out-dir", default=None, metavar="DIR",
                   help="write one JSON per object into DIR (created if missing), named after "
                        "the object: part.json for part.stl, cylinder.json for shape:cylinder")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar and no table")
    p.set_defaults(run=_cmd_plan)

    p = sub.add_parser("grippers", help="list the bundled grippers")
    p.set_defaults(run=_cmd_grippers)

    p = sub.add_parser("samplers", help="list the installed samplers")
    p.set_defaults(run=_cmd_samplers)

    p = sub.add_parser("tag", help="write a tagged copy of a stock URDF (gripper registration)", description=(
        "Write a copy of URDF with <isf:contact> tags added (the vendor file is only read), "
        "validate it and show what every tag selected. Without --contact, one contact "
        "surface per fingertip is suggested, facing the other fingertips."))
    p.add_argument("urdf", help="the stock URDF")
    p.add_argument("--out", "-o", required=True, help="the tagged copy to write")
    p.add_argument("--contact", action="append", default=None, metavar="SPEC",
                   help="a contact surface as key=value words, e.g. "
                        "'name=left link=left_finger normal=0,-1,0 max_angle=0.3' (repeatable)")
    p.add_argument("--links", default=None, help="comma-separated fingertip links for the suggestion")
    p.add_argument("--points", type=int, default=256, help="points per suggested surface (default 256)")
    p.add_argument("--tip-fraction", type=float, default=0.5,
                   help="fraction of a suggested pad kept, from the fingertip (default 0.5; 1 = whole pad)")
    p.add_argument("--palm-link", default=None, help="the link that approaches the object (default: root)")
    p.add_argument("--approach", default="auto",
                   help="approach direction in the palm frame: auto (default), none, or X,Y,Z")
    p.add_argument("--initial", action="append", default=[], metavar="JOINT=VALUE",
                   help="initial value of an actuated joint (repeatable)")
    p.add_argument("--package", action="append", default=[], metavar="PKG=DIR",
                   help="folder of a package:// package (repeatable)")
    p.add_argument("--replace", action="store_true", help="replace isf tags the source already has")
    p.add_argument("--export", default=None, metavar="FILE",
                   help="also write the gripper with the selected faces in red (PLY/GLB/OBJ)")
    p.set_defaults(run=_cmd_tag)

    p = sub.add_parser("inspect", help="show a gripper's joints, limits, contact surfaces and problems")
    p.add_argument("gripper", help="bundled gripper name or URDF path")
    p.set_defaults(run=_cmd_inspect)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.run(args)
    except ISFError as err:
        print(f"isf: error: {_one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("isf: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `isf plan ... | head`: the reader left, not an error of ours
        sys.stderr.close()
        return EXIT_OK


def _one_line(err: Exception) -> str:
    return " ".join(str(err).split())


# ----------------------------------------------------------------------------- commands
def _cmd_plan(args: argparse.Namespace) -> int:
    from .collision.checker import Plane
    from .config import FitConfig, config_from_text
    from .gripper.loading import load_gripper
    from .object.specs import check_object_spec, open_object
    from .planning.plan_json import write_plan_json
    from .planning.planner import plan
    from .repair.clearance import RepairConfig
    from .samplers import get_sampler

    outputs = _output_paths(args.object_specs, args.out, args.out_dir)
    if args.top is not None and args.top < 1:
        raise InvalidInputError(f"--top must be >= 1, got {args.top}")
    for flag, value in (("--samples", args.samples), ("--batch-size", args.batch_size),
                        ("--workers", args.workers)):
        if value < 1:
            raise InvalidInputError(f"{flag} must be >= 1, got {value}")
    if args.batch_size > 1 and args.workers > 1:
        raise InvalidInputError("--batch-size and --workers cannot both exceed 1: choose lockstep "
                                "batches or worker threads")
    if args.no_repair and args.repair:
        raise InvalidInputError("--no-repair and --repair exclude each other: drop one")
    config = config_from_text(FitConfig, _pairs(args.fit, "--fit"))
    repair = False if args.no_repair else (
        config_from_text(RepairConfig, _pairs(args.repair, "--repair")) if args.repair else True)
    gripper = load_gripper(args.gripper)
    for spec in args.object_specs[1:]:  # a missing file or unknown name fails before any plan
        check_object_spec(spec)
    first = open_object(args.object_specs[0], units=args.units, scale=args.scale)
    obstacles = [Plane.table(args.table)] if args.table is not None else []
    get_sampler(args.sampler)  # a bad name fails before the kernels load
    _compile_kernels(quiet=args.quiet)
    show = not args.quiet and sys.stderr.isatty()
    found_everywhere = True
    for index, (spec, out) in enumerate(zip(args.object_specs, outputs)):
        progress = _ProgressBar(sys.stderr) if show else None
        try:
            # the others load in turn: one object (and what its plan builds) in memory at a time
            obj = first if index == 0 else open_object(spec, units=args.units, scale=args.scale)
            first = None
            result = plan(gripper, obj, samples=args.samples, sampler=args.sampler,
                          seed=args.seed, batch_size=args.batch_size, workers=args.workers,
                          config=config, obstacles=obstacles, repair_collisions=repair,
                          progress=progress)
        except ISFError as err:
            if len(outputs) == 1:
                raise
            raise ISFError(f"{spec}: {_one_line(err)} (the {index} object(s) before it are "
                           "planned, their files complete)") from err
        finally:
            if progress:
                progress.close()
        out.parent.mkdir(exist_ok=True)  # --out-dir: made once there is a plan to write
        write_plan_json(result, out, top=args.top)
        if not args.quiet:
            print(_summary(result, args.top or 10))
        s = result.stats
        written = len(result.grasps) if args.top is None else min(args.top, len(result.grasps))
        print(f"{s.collision_free}/{s.samples} collision-free grasps in {s.total_time:.2f} s; "
              f"wrote {written} grasps to {out.resolve()}", flush=True)
        found_everywhere = found_everywhere and s.collision_free > 0
        del obj, result
    return EXIT_OK if found_everywhere else EXIT_NOTHING_FOUND


def _output_paths(specs: list[str], out: str | None, out_dir: str | None) -> list[Path]:
    """The JSON file of each object spec: ``out`` (default ``grasps.json``) for one object, else
    ``out_dir/<name>.json`` (:func:`_output_name`).

    Raises:
        InvalidInputError: both or, for several objects, neither of ``out`` and ``out_dir``;
            a missing folder above them; two objects with the same output name.
    """
    if out is not None and out_dir is not None:
        raise InvalidInputError("--out and --out-dir exclude each other: --out names the file of "
                                "one object, --out-dir a folder for one file per object")
    if out_dir is None:
        if len(specs) > 1:
            raise InvalidInputError(f"{len(specs)} objects need --out-dir DIR (one JSON per "
                                    "object); --out names the file of one object")
        path = Path(out or "grasps.json")
        if not path.parent.is_dir():
            raise InvalidInputError(f"output folder {path.parent} does not exist: create it or "
                                    "pass another --out")
        return [path]
    folder = Path(out_dir)
    if not folder.parent.is_dir() or (folder.exists() and not folder.is_dir()):
        raise InvalidInputError(f"--out-dir {folder} cannot be a folder (its parent is missing "
                                "or it is a file): pass another --out-dir")
    seen: dict[str, str] = {}
    for spec in specs:
        name = _output_name(spec)
        if name in seen:
            raise InvalidInputError(f"objects {seen[name]!r} and {spec!r} would both write "
                                    f"{folder / name}: plan them in separate runs or rename a file")
        seen[name] = spec
    return [folder / name for name in seen]


def _output_name(spec: str) -> str:
    """The JSON file name of an object spec: a file's stem (``part.stl`` -> ``part.json``), or
    the name after ``shape:`` / ``asset:`` with ``:`` and ``/`` turned into ``-``
    (``asset:ycb:Banana`` -> ``ycb-Banana.json``)."""
    for prefix in ("shape:", "asset:"):
        if spec.startswith(prefix):
            return spec.removeprefix(prefix).replace(":", "-").replace("/", "-") + ".json"
    return Path(spec).stem + ".json"


def _compile_kernels(quiet: bool) -> None:
    """Compile (or load) the kernels before planning, so the plan's times leave them out; when
    that takes more than a few seconds (a first run: loading compiled kernels takes about one),
    say what is happening."""
    from .warming import warm_up

    notice = threading.Timer(_COMPILE_NOTICE_AFTER, lambda: print(
        "isf: compiling its numerical kernels for this machine (once after installing or "
        "upgrading isf: about a minute and a half) ...", file=sys.stderr, flush=True))
    if not quiet:
        notice.start()
    try:
        warm_up()
    finally:
        notice.cancel()


_COMPILE_NOTICE_AFTER = 4.0
"""Seconds of warm-up after which ``isf plan`` says it is compiling (loading the compiled
kernels takes about a second; compiling them, tens of seconds)."""


def _cmd_grippers(args: argparse.Namespace) -> int:
    from .gripper.bundled import bundled_grippers

    for name, path in bundled_grippers().items():
        print(f"{name:<16} {path}")
    return EXIT_OK


def _cmd_samplers(args: argparse.Namespace) -> int:
    from .samplers import available_samplers

    for name, info in available_samplers(load=True).items():
        description = getattr(info, "description", "") or ""
        print(f"{name:<10} {info.source:<28} {description}")
    return EXIT_OK


def _pairs(words: list[str], what: str) -> dict[str, str]:
    from .exceptions import InvalidInputError

    out = {}
    for word in words:
        key, eq, value = word.partition("=")
        if not eq or not key:
            raise InvalidInputError(f"{what} {word!r} must look like NAME=VALUE")
        out[key] = value
    return out


def _cmd_tag(args: argparse.Namespace) -> int:
    from .exceptions import InvalidInputError
    from .registration import ContactSpec, suggest_approach, suggest_contacts, tag_urdf

    package_dirs = _pairs(args.package, "--package") or None
    try:
        initial = {k: float(v) for k, v in _pairs(args.initial, "--initial").items()} or None
    except ValueError:
        raise InvalidInputError("--initial values must be numbers (metres or radians)") from None
    links = args.links.split(",") if args.links else None
    if args.contact:
        contacts = [ContactSpec.parse(text) for text in args.contact]
    else:
        contacts = suggest_contacts(args.urdf, links=links, initial=initial, package_dirs=package_dirs,
                                    points=args.points, tip_fraction=args.tip_fraction)
    if args.approach == "auto":
        approach = suggest_approach(args.urdf, palm_link=args.palm_link, links=links, initial=initial,
                                    package_dirs=package_dirs)
    elif args.approach == "none":
        approach = None
    else:
        try:
            approach = [float(v) for v in args.approach.split(",")]
        except ValueError:
            approach = []
        if len(approach) != 3:
            raise InvalidInputError(f"--approach {args.approach!r} must be auto, none or X,Y,Z")
    preview = tag_urdf(args.urdf, args.out, contacts, palm_link=args.palm_link, approach=approach,
                       initial=initial, package_dirs=package_dirs, replace_tags=args.replace)
    print(preview.format())
    if args.export:
        print(f"selected faces shown in {preview.export(args.export)}")
    return EXIT_OK if preview.ok else EXIT_NOTHING_FOUND


def _cmd_inspect(args: argparse.Namespace) -> int:
    from .gripper.loading import format_report, inspect_gripper

    report = inspect_gripper(args.gripper)
    print(format_report(report))
    return EXIT_OK if report.ok else EXIT_NOTHING_FOUND


# ----------------------------------------------------------------------------- output
class _ProgressBar:
    """A one-line progress bar on a terminal stream."""

    def __init__(self, stream, width: int = 30):
        self.stream, self.width, self.free = stream, width, 0

    def __call__(self, done: int, total: int, grasp) -> None:
        self.free += grasp.collision_free
        filled = round(self.width * done / total)
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r[{bar}] {done}/{total} samples, {self.free} collision-free")
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\n")
        self.stream.flush()


def _summary(result, top: int) -> str:
    head = f"{'rank':>4}  {'free':<5} {'dist mm':>8} {'misalign deg':>12} {'clear mm':>9}  {'position (m)':<26} joints"
    lines = [f"{result.gripper} on {result.object}, sampler {result.sampler}, seed {result.seed}", head]
    for rank, g in enumerate(result.grasps[:top], start=1):
        p = g.T_object_gripper[:3, 3]
        joints = " ".join(f"{k}={v:.4g}" for k, v in g.joints.items())
        lines.append(
            f"{rank:>4}  {'yes' if g.collision_free else 'no':<5} {g.fit.mean_distance * 1e3:>8.3f} "
            f"{math.degrees(g.fit.normal_misalignment):>12.2f} {g.collision.clearance * 1e3:>9.2f}  "
            f"{p[0]:+.4f} {p[1]:+.4f} {p[2]:+.4f}     {joints}"
        )
    return "\n".join(lines)
