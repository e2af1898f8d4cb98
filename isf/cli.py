"""The ``isf`` command line: ``plan``, ``grippers``, ``samplers``, ``tag``, ``inspect``, ``compile``.

Exit codes (docs/cli.md):

* 0: success;
* 1: a plan found no valid grasp (collision-free with every contact surface touching the
  object) for some object it planned, or ``inspect``/``tag`` found problems in the gripper;
* 2: a usage or input error: one line on stderr, no traceback, no output file written;
* 3: an error inside isf (a bug): one line that says so and how to report it; ``-v`` adds the
  traceback;
* 130: interrupted (Ctrl-C): the files of the objects already planned are kept, complete; no
  partial file is left.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import math
import os
import signal
import sys
import threading
import traceback
import warnings
from pathlib import Path

from . import __version__
from .exceptions import InvalidInputError, ISFError, ISFWarning

__all__ = ["main"]

EXIT_OK, EXIT_NOTHING_FOUND, EXIT_USAGE, EXIT_BUG, EXIT_INTERRUPTED = 0, 1, 2, 3, 130

COMMAND_MODULES: tuple[str, ...] = ("show", "export", "validate", "batch")
"""Subcommands defined in modules of :mod:`isf.commands`, in the order ``isf --help`` lists them
(each module's ``add_parser(subparsers)`` adds its parser and sets ``run``)."""

REPORT_BUGS_TO = "isf's issue tracker"
"""Where the exit-3 message asks users to report a bug."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="isf", description="Grasp planning for customized grippers by Iterative Surface Fitting."
    )
    parser.add_argument("--version", action="version", version=f"isf {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("plan", help="plan grasps of an object", description=(
        "Plan grasps of OBJECT (or of what a depth camera saw: --scene) with GRIPPER and write "
        "them as JSON. GRIPPER is a bundled name "
        "(see 'isf grippers') or a tagged URDF; OBJECT is a mesh or point-cloud file, "
        "shape:NAME (cylinder, box, sphere, capsule, torus) or asset:NAME (e.g. asset:bunny). "
        "Several --object plan one after the other in one run, with the same parameters, and "
        "write one JSON each into --out-dir: the run starts up once (loading isf and its "
        "compiled kernels takes seconds, longer than a plan)."))
    p.add_argument("--gripper", "-g", required=True, help="bundled gripper name or URDF path")
    p.add_argument("--object", "-o", action="append", dest="object_specs", metavar="OBJECT",
                   help="mesh/cloud file, shape:NAME or asset:NAME (repeatable, with --out-dir)")
    p.add_argument("--scene", default=None, metavar="FILE",
                   help="instead of --object: what a depth camera saw, a depth image (16-bit PNG "
                        "or NPY (H, W)) or a point cloud (PLY, PCD, XYZ, NPY (N, 3)); grasps come "
                        "out in the scene frame (docs/tutorial-depth-camera.md)")
    p.add_argument("--intrinsics", default=None, metavar="FX,FY,CX,CY",
                   help="the depth camera's pinhole intrinsics, pixels (needed for a depth image)")
    p.add_argument("--camera-pose", default=None, metavar="FILE|16 NUMBERS",
                   help="T_scene_camera, the camera's pose in the scene frame: a .npy or text file "
                        "of a 4x4 matrix, or 16 comma-separated numbers row by row (default: the "
                        "scene frame is the camera frame: x right, y down, z forward)")
    p.add_argument("--depth-scale", type=float, default=None, metavar="S",
                   help="metres per unit of --scene (default 0.001 for integer depth images, "
                        "1 otherwise)")
    p.add_argument("--cloud-frame", choices=("camera", "scene"), default="camera",
                   help="the frame of a --scene point cloud's coordinates (default camera)")
    p.add_argument("--samples", "-n", type=int, default=60, help="samples to evaluate (default 60, at most 100000)")
    p.add_argument("--sampler", "-s", default="regret", help="sampler name (default regret; see 'isf samplers')")
    p.add_argument("--sampler-param", action="append", default=[], metavar="KEY=VALUE",
                   help="a parameter of the sampler, checked by the sampler itself, e.g. "
                        "orientation=random (the paper's) or n_clusters=8 for regret (repeatable; "
                        "numbers are read as numbers; docs/samplers.md lists them)")
    p.add_argument("--seed", type=int, default=0, help="random seed, >= 0 (default 0)")
    p.add_argument("--batch-size", type=int, default=None, metavar="B",
                   help="samples fitted at once in lockstep (default: isf.plan's, one at a time: "
                        "the paper's sequential loop)")
    p.add_argument("--workers", "-j", type=int, default=1, metavar="W",
                   help="threads that fit, check and repair samples side by side (default 1, at most 256); the "
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
    p.add_argument("--no-centring", action="store_true",
                   help="keep valid grasps where the fit left them instead of sliding them "
                        "toward the centre of mass along their contact faces (docs/quality.md)")
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="units of the object file (default m)")
    p.add_argument("--scale", type=float, default=1.0, help="extra scale factor for the object")
    p.add_argument("--table", default=None, metavar="Z|auto",
                   help="a table plane at height Z (object or scene frame, metres): grasps below "
                        "it are rejected; with --scene, 'auto' finds it (RANSAC) and removes its "
                        "points from the surface")
    p.add_argument("--top", type=int, default=None, metavar="K", help="keep only the best K grasps in the output")
    p.add_argument("--out", default=None,
                   help="output JSON file of one object (default grasps.json); '-' writes the JSON "
                        "to stdout (the table and messages then go to stderr)")
    p.add_argument("--pregrasp-distance", type=float, default=None, metavar="M",
                   help="how far each grasp's pre-grasp pose backs off along the approach axis, "
                        "fingers opened (default 0.1 m)")
    p.add_argument("--duplicate-distance", type=float, default=0.01, metavar="M",
                   help="a grasp whose TCP lies within M of a better grasp's (and within "
                        "--duplicate-angle) repeats it: it is marked duplicate_of and ranked after "
                        "the distinct grasps (default 0.01 m)")
    p.add_argument("--duplicate-angle", type=float, default=30.0, metavar="DEG",
                   help="largest TCP orientation difference of a duplicate, degrees, after the "
                        "gripper's symmetric turns (default 30)")
    p.add_argument("--symmetry", default="auto", metavar="auto|N",
                   help="order of the gripper's rotational symmetry about its approach axis (2: a "
                        "parallel jaw turned by 180 degrees grips the same way); auto (default) "
                        "detects it, 1 declares none")
    p.add_argument("--keep-duplicates", action="store_true",
                   help="keep the plain ranking: no grasp is marked duplicate_of")
    p.add_argument("--rank", choices=("quality", "fit"), default="quality",
                   help="rank valid grasps by what their contacts resist (quality, default: holding "
                        "the object's weight in six gravity directions, then contacts nearest the "
                        "centre of mass, then the Ferrari-Canny epsilon, then the fitting error; "
                        "docs/quality.md) or by fitting error "
                        "alone (fit, the paper's ranking)")
    p.add_argument("--friction", type=float, default=0.5, metavar="MU",
                   help="Coulomb friction coefficient of the contacts for --rank quality "
                        "(default 0.5)")
    p.add_argument("--mass", type=float, default=0.3, metavar="KG",
                   help="the object's mass for --rank quality, kg: a grasp holds when its "
                        "contacts resist this weight (default 0.3)")
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
    p.add_argument("--tcp", default="auto", metavar="auto|none|X,Y,Z",
                   help="tool-centre point in the palm link's frame, metres (<isf:gripper "
                        "tcp_link tcp_origin>): auto (default) puts it between the fingertips")
    p.add_argument("--initial", action="append", default=[], metavar="JOINT=VALUE",
                   help="initial value of an actuated joint (repeatable)")
    p.add_argument("--package", action="append", default=[], metavar="PKG=DIR",
                   help="folder of a package:// package (repeatable)")
    p.add_argument("--closing", choices=("auto", "none"), default="auto",
                   help="<isf:closing> signs for isf validate: auto (default) suggests each "
                        "joint's from the contact normals at the initial configuration; none "
                        "writes none")
    p.add_argument("--replace", action="store_true", help="replace isf tags the source already has")
    p.add_argument("--export", default=None, metavar="FILE",
                   help="also write the gripper with the selected faces in red (PLY/GLB/OBJ)")
    p.set_defaults(run=_cmd_tag)

    p = sub.add_parser("inspect", help="show a gripper's joints, limits, contact surfaces and problems")
    p.add_argument("gripper", help="bundled gripper name or URDF path")
    p.add_argument("--export", default=None, metavar="FILE",
                   help="also write the gripper with its contact surfaces' faces in red (PLY/GLB/OBJ)")
    p.set_defaults(run=_cmd_inspect)

    p = sub.add_parser("compile", help="compile the numerical kernels into the cache now", description=(
        "Compile isf's numerical kernels for this machine into numba's cache (NUMBA_CACHE_DIR "
        "moves it), as the first 'isf plan' would: for container images and CI. Kernels already "
        "cached are loaded, not compiled again."))
    p.add_argument("-q", "--quiet", action="store_true", help="do not count the kernels on stderr")
    p.set_defaults(run=_cmd_compile)

    for name in COMMAND_MODULES:
        importlib.import_module(f"{__package__}.commands.{name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (see the module docstring).

    Called without ``argv`` (as the ``isf`` command), a Ctrl-C that comes once the command is
    done is ignored: its output is complete, and the exit code says how it went.
    """
    try:
        return _run(argv)
    finally:
        if argv is None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run(argv: list[str] | None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return args.run(args)
    except ISFError as err:
        print(f"isf: error: {_one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:  # e.g. `isf plan ... | head`: the reader left, not an error of ours
        sys.stderr.close()
        return EXIT_OK
    except Exception as err:  # anything else is a bug of isf, never "nothing found"
        if _caused_by_interrupt(err):
            return _interrupted()
        if args.verbose:
            traceback.print_exc(file=sys.stderr)
        print(f"isf: internal error (a bug in isf {__version__}): {type(err).__name__}: "
              f"{_one_line(err)[:300]}; please report it on {REPORT_BUGS_TO} with the command "
              f"that caused it{'' if args.verbose else ' and the traceback of isf -v'}",
              file=sys.stderr)
        return EXIT_BUG


def _interrupted() -> int:
    print("isf: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def _exit_interrupted(signum, frame) -> None:
    """SIGINT handler that ends the process at once with exit code 130."""
    os.write(2, b"\nisf: interrupted\n" if sys.stderr.isatty() else b"isf: interrupted\n")
    os._exit(EXIT_INTERRUPTED)


def _caused_by_interrupt(err: BaseException) -> bool:
    """True when a KeyboardInterrupt is in ``err``'s chain: Python reports one raised while a
    compiled kernel returned as a ``SystemError`` whose context is the interrupt."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """isf's warnings as one line on stderr; others as Python shows them."""
    if issubclass(category, ISFWarning):
        print(f"isf: warning: {_one_line(message)}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _one_line(err: Exception | Warning | str) -> str:
    return " ".join(str(err).split())


class _Interrupts:
    """Ctrl-C during ``isf plan``: SIGINT is recorded and acted on at the next safe point
    (after the set-up, between two samples, between two objects, after a file is written), so
    it never lands inside a compiled kernel, a write, or an import of a library that swallows
    exceptions while it imports (trimesh does); only the kernel compilation, which can take
    minutes and writes no output file, is interrupted at once (:meth:`immediate`). Outside the
    main thread (a test calling :func:`main`) signals cannot be handled, and in a process
    started with SIGINT ignored (``isf plan ... &`` in a script: the shell ignores it for
    background jobs) it stays ignored, as Python leaves it: nothing changes."""

    def __init__(self) -> None:
        self.pending = False
        self._previous = None

    def __enter__(self) -> _Interrupts:
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
            self._previous = signal.signal(signal.SIGINT, self._record)
        return self

    def _record(self, signum, frame) -> None:
        self.pending = True

    def check(self) -> None:
        """Raise KeyboardInterrupt if Ctrl-C was pressed."""
        if self.pending:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def immediate(self):
        """A block that Ctrl-C ends at once: ``isf: interrupted``, exit 130, no clean-up.

        Not a KeyboardInterrupt: raised inside code that numba compiles from source with
        ``exec``, CPython records it as unhandled and ends the process by SIGINT at exit
        whatever the command returns.
        """
        self.check()
        if self._previous is None:
            yield
            return
        signal.signal(signal.SIGINT, _exit_interrupted)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, self._record)

    def __exit__(self, kind, error, trace) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        if kind is None:
            self.check()


# ----------------------------------------------------------------------------- commands
def _cmd_plan(args: argparse.Namespace) -> int:
    """``isf plan``: Ctrl-C is acted on at safe points (:class:`_Interrupts`)."""
    with _Interrupts() as interrupts:
        from .collision.checker import Plane
        from .config import FitConfig, config_from_text
        from .gripper.loading import load_gripper
        from .object.specs import check_object_spec, open_object
        from .planning.planner import BATCH_SIZE
        from .repair.clearance import RepairConfig
        from .samplers import get_sampler

        args.batch_size = BATCH_SIZE if args.batch_size is None else args.batch_size
        _check_inputs(args)
        outputs = _output_paths(args.object_specs, args.out, args.out_dir)
        if args.top is not None and args.top < 1:
            raise InvalidInputError(f"--top must be >= 1, got {args.top}")
        if args.seed < 0:
            raise InvalidInputError(f"--seed must be >= 0, got {args.seed}")
        from .planning.planner import MAX_SAMPLES, MAX_WORKERS

        for flag, value, limit in (("--samples", args.samples, MAX_SAMPLES),
                                   ("--batch-size", args.batch_size, None),
                                   ("--workers", args.workers, MAX_WORKERS)):
            if value < 1:
                raise InvalidInputError(f"{flag} must be >= 1, got {value}")
            if limit is not None and value > limit:
                raise InvalidInputError(f"{flag} must be at most {limit}, got {value}")
        if args.batch_size > 1 and args.workers > 1:
            raise InvalidInputError("--batch-size and --workers cannot both exceed 1: choose lockstep "
                                    "batches or worker threads")
        if args.no_repair and args.repair:
            raise InvalidInputError("--no-repair and --repair exclude each other: drop one")
        args.diversity = _diversity(args)
        args.quality_config = _quality_config(args)
        if args.pregrasp_distance is not None and not 0 <= args.pregrasp_distance < math.inf:
            raise InvalidInputError(f"--pregrasp-distance must be a distance >= 0 in metres, got "
                                    f"{args.pregrasp_distance}")
        config = config_from_text(FitConfig, _pairs(args.fit, "--fit"))
        repair = False if args.no_repair else (
            config_from_text(RepairConfig, _pairs(args.repair, "--repair")) if args.repair else True)
        gripper = load_gripper(args.gripper)
        for spec in args.object_specs[1:]:  # a missing file or unknown name fails before any plan
            check_object_spec(spec)
        if args.scene is not None:
            first, obstacles = _open_scene(args), []  # the scene carries its table
        else:
            first = open_object(args.object_specs[0], units=args.units, scale=args.scale)
            obstacles = [Plane.table(args.table)] if args.table is not None else []
        args.sampler_params = _sampler_params(args.sampler_param)
        get_sampler(args.sampler, **args.sampler_params)  # a bad name or parameter fails now
        with interrupts.immediate():
            _compile_kernels(quiet=args.quiet)
        show = not args.quiet and sys.stderr.isatty()
        found_everywhere = True
        for index, (spec, out) in enumerate(zip(args.object_specs, outputs)):
            interrupts.check()
            found = _plan_one(args, index, spec, out, first, gripper, config, repair, obstacles,
                              _ProgressBar(sys.stderr) if show else None, interrupts)
            first = None
            found_everywhere = found_everywhere and found
        return EXIT_OK if found_everywhere else EXIT_NOTHING_FOUND


_TABLE_LIMIT = 1e3
"""Largest ``--table`` height accepted, metres from the object frame's origin."""


def _check_inputs(args: argparse.Namespace) -> None:
    """Check ``--object``/``--scene`` and ``--table`` of ``isf plan``; a scene becomes the one
    object spec, and a numeric ``--table`` a float.

    Raises:
        InvalidInputError: neither or both of ``--object`` and ``--scene``; camera options
            without ``--scene``; ``--table`` neither a number nor (with ``--scene``) ``auto``.
    """
    if (args.scene is None) == (not args.object_specs):
        raise InvalidInputError("isf plan needs --object OBJECT (a mesh, cloud or shape) or "
                                "--scene FILE (what a depth camera saw), not both")
    camera = [flag for flag, value in (("--intrinsics", args.intrinsics),
                                       ("--camera-pose", args.camera_pose),
                                       ("--depth-scale", args.depth_scale))
              if value is not None] + (["--cloud-frame"] if args.cloud_frame != "camera" else [])
    if args.scene is None and camera:
        raise InvalidInputError(f"{', '.join(camera)} describe a --scene: pass --scene FILE, or "
                                "drop them to plan on an --object")
    if args.scene is not None:
        if args.units != "m" or args.scale != 1.0:
            raise InvalidInputError("--units and --scale apply to --object; a --scene's units "
                                    "are set by --depth-scale")
        args.object_specs = [args.scene]
    if args.table is None or (args.table == "auto" and args.scene is not None):
        return
    try:
        args.table = float(args.table)
    except ValueError:
        hint = "a height in metres or 'auto'" if args.scene is not None else \
            "a height in metres ('auto' needs --scene)"
        raise InvalidInputError(f"--table {args.table!r} must be {hint}") from None
    if not abs(args.table) <= _TABLE_LIMIT:
        raise InvalidInputError(f"--table {args.table:g} is not a height within {_TABLE_LIMIT:g} m "
                                "of the object's frame: pass the table's height in metres")


def _quality_config(args: argparse.Namespace):
    """The :class:`isf.quality.QualityConfig` of ``isf plan --rank quality`` (None with
    ``--rank fit``).

    Raises:
        InvalidInputError: ``--friction`` is negative or not finite, or ``--mass`` is not a
            finite number > 0.
    """
    from .quality import QualityConfig

    if args.rank == "fit":
        return None
    return QualityConfig(friction=args.friction, mass=args.mass)


def _diversity(args: argparse.Namespace):
    """The :class:`isf.planning.diversity.Diversity` of ``isf plan``, or None
    (``--keep-duplicates``).

    Raises:
        InvalidInputError: a negative distance or angle, or ``--symmetry`` neither ``auto`` nor
            an integer >= 1.
    """
    from .planning.diversity import Diversity

    if args.keep_duplicates:
        return None
    symmetry = args.symmetry
    if symmetry != "auto":
        try:
            symmetry = int(symmetry)
        except ValueError:
            raise InvalidInputError(f"--symmetry {args.symmetry!r} must be auto or an integer "
                                    ">= 1") from None
    return Diversity(args.duplicate_distance, math.radians(args.duplicate_angle), symmetry)


def _provenance(args: argparse.Namespace, spec: str):
    """The :class:`isf.planning.plan_json.Provenance` of one object of ``isf plan``: its file
    (an ``asset:`` spec's file too), units, scale and every option of the command."""
    from .planning.plan_json import Provenance

    object_file = None
    if spec.startswith("asset:"):
        from .assets import benchmark_object

        object_file = benchmark_object(spec.removeprefix("asset:")).path
    elif not spec.startswith("shape:"):
        object_file = spec
    parameters = {key: value for key, value in vars(args).items()
                  if key not in ("run", "diversity", "quality_config") and isinstance(
                      value, (str, int, float, bool, list, dict, type(None)))}
    return Provenance(object_file, args.units, args.scale, {"object": spec, **parameters})


def _sampler_params(words: list[str]) -> dict[str, object]:
    """``--sampler-param KEY=VALUE`` words as keyword arguments: a value that reads as an
    integer or a number becomes one, any other stays text (the sampler checks them)."""
    from .config import number_or_text

    return {key: number_or_text(text) for key, text in _pairs(words, "--sampler-param").items()}


def _open_scene(args: argparse.Namespace):
    """The :class:`isf.scene.Scene` of ``isf plan --scene``."""
    from .scene import load_scene

    return load_scene(args.scene, intrinsics=args.intrinsics, T_scene_camera=args.camera_pose,
                      depth_scale=args.depth_scale, cloud_frame=args.cloud_frame,
                      table=args.table)


def _plan_one(args, index, spec, out, obj, gripper, config, repair, obstacles, bar,
              interrupts: _Interrupts) -> bool:
    """Plan one object of ``isf plan`` and write its file; True when a valid grasp was found.

    ``obj`` is the object already opened, or None to open ``spec``; SIGINT is acted on between
    samples (``interrupts``)."""
    from .object.specs import open_object
    from .planning.plan_json import plan_json_text, write_plan_json
    from .planning.planner import plan
    from .samplers import get_sampler

    to_stdout = str(out) == "-"  # --out -: the JSON on stdout, everything else on stderr
    messages = sys.stderr if to_stdout else sys.stdout

    def progress(done: int, total: int, grasp) -> None:
        interrupts.check()
        if bar is not None:
            bar(done, total, grasp)

    n_objects = len(args.object_specs)
    try:
        try:
            # the others load in turn: one object (and what its plan builds) in memory at a time
            if obj is None:
                obj = open_object(spec, units=args.units, scale=args.scale)
            sampler = get_sampler(args.sampler, **args.sampler_params)  # one per object: a
            # sampler holds the object it was reset on, which must go with its plan
            result = plan(gripper, obj, samples=args.samples, sampler=sampler,
                          seed=args.seed, batch_size=args.batch_size, workers=args.workers,
                          config=config, obstacles=obstacles, repair_collisions=repair,
                          centring=not args.no_centring,
                          progress=progress, diversity=args.diversity, rank=args.rank,
                          quality=args.quality_config)
        finally:
            if bar is not None:
                bar.close()
        options = dict(top=args.top, provenance=_provenance(args, spec))
        if args.pregrasp_distance is not None:
            options["pregrasp_distance"] = args.pregrasp_distance
        if to_stdout:
            sys.stdout.write(plan_json_text(result, **options))
            sys.stdout.flush()
        else:
            out.parent.mkdir(exist_ok=True)  # --out-dir: made once there is a plan to write
            write_plan_json(result, out, **options)
    except ISFError as err:
        if n_objects == 1:
            raise
        raise ISFError(f"{spec}: {_one_line(err)} (the {index} object(s) before it are "
                       "planned, their files complete)") from err
    if not args.quiet:
        print(_summary(result, args.top or 10), file=messages)
    s = result.stats
    written = len(result.grasps) if args.top is None else min(args.top, len(result.grasps))
    found = f"{s.valid}/{s.samples} valid grasps" if s.valid else "no valid grasp found: 0/" \
        f"{s.samples} valid"
    print(f"{found} (collision-free, every contact surface touching; {s.collision_free} "
          f"collision-free) in {s.total_time:.2f} s; wrote {written} grasps to "
          f"{'stdout' if to_stdout else out.resolve()}", file=messages, flush=True)
    return s.valid > 0


def _output_paths(specs: list[str], out: str | None, out_dir: str | None) -> list[Path]:
    """The JSON file of each object spec: ``out`` (default ``grasps.json``) for one object, else
    ``out_dir/<name>.json`` (:func:`_output_name`).

    Raises:
        InvalidInputError: both or, for several objects, neither of ``out`` and ``out_dir``;
            a missing folder above them; two objects with the same output name.
        OutputFileError: an output path that cannot become a regular file
            (:func:`isf.output_files.check_output_path`).
    """
    from .output_files import check_output_path

    if out is not None and out_dir is not None:
        raise InvalidInputError("--out and --out-dir exclude each other: --out names the file of "
                                "one object, --out-dir a folder for one file per object")
    if out_dir is None:
        if len(specs) > 1:
            raise InvalidInputError(f"{len(specs)} objects need --out-dir DIR (one JSON per "
                                    "object); --out names the file of one object")
        if out == "-":
            return [Path("-")]  # stdout
        return [check_output_path(out or "grasps.json", "--out file")]
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
    if folder.is_dir():  # else it is created once there is a plan to write
        for name in seen:
            check_output_path(folder / name, "output file")
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
    kernels must be compiled (the first run after installing or upgrading isf), count them on
    stderr."""
    from .warming import warm_up

    warm_up(progress=None if quiet else _compile_progress)


def _compile_progress(done: int, total: int) -> None:
    """Show that ``done`` of ``total`` kernels are compiled: one line rewritten on a terminal,
    a line per tenth otherwise."""
    text = f"isf: compiling its numerical kernels for this machine (once): {done}/{total}"
    if sys.stderr.isatty():
        print(f"\r{text}", end="\n" if done == total else "", file=sys.stderr, flush=True)
    elif done * 10 // total > (done - 1) * 10 // total:  # at 0 and at each tenth
        print(text, file=sys.stderr, flush=True)


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
    from .output_files import check_output_path
    from .registration import ContactSpec, suggest_approach, suggest_contacts, tag_urdf
    from .registration.preview import check_export_path

    if Path(args.out).parent.is_dir():  # both refused before anything is written
        check_output_path(args.out, "--out file")
    if args.export:
        check_export_path(args.export)
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
                       initial=initial, package_dirs=package_dirs, replace_tags=args.replace,
                       tcp=_tag_tcp(args, links, initial, package_dirs),
                       closing="suggest" if args.closing == "auto" else None)
    print(preview.format())
    if args.export:
        print(f"selected faces shown in {preview.export(args.export)}")
    return EXIT_OK if preview.ok else EXIT_NOTHING_FOUND


def _tag_tcp(args: argparse.Namespace, links, initial, package_dirs):
    """The tool-centre point of ``isf tag --tcp``: suggested, none, or given in the palm link."""
    from .registration import SuggestedTCP, suggest_tcp

    if args.tcp == "none":
        return None
    if args.tcp == "auto":
        return suggest_tcp(args.urdf, palm_link=args.palm_link, links=links, initial=initial,
                           package_dirs=package_dirs)
    try:
        origin = tuple(float(v) for v in args.tcp.split(","))
    except ValueError:
        origin = ()
    if len(origin) != 3:
        raise InvalidInputError(f"--tcp {args.tcp!r} must be auto, none or X,Y,Z (metres)")
    if args.palm_link is None:
        from .gripper.loading import inspect_gripper

        palm = inspect_gripper(args.urdf).root_link
    else:
        palm = args.palm_link
    return SuggestedTCP(palm, origin)


def _cmd_inspect(args: argparse.Namespace) -> int:
    from .gripper.loading import format_report, inspect_gripper, load_gripper
    from .registration.occlusion import contact_warnings
    from .registration.preview import check_export_path, preview_tagged

    if args.export:
        check_export_path(args.export)
    report = inspect_gripper(args.gripper)
    print(format_report(report))
    if not report.ok:
        return EXIT_NOTHING_FOUND
    for warning in contact_warnings(load_gripper(args.gripper)):
        print(f"warning: {warning}")
    if args.export:
        preview = preview_tagged(report.urdf_path, report=report)
        print(f"contact surfaces shown in {preview.export(args.export)}")
    return EXIT_OK


# ----------------------------------------------------------------------------- output
class _ProgressBar:
    """A one-line progress bar on a terminal stream."""

    def __init__(self, stream, width: int = 30):
        self.stream, self.width, self.valid = stream, width, 0

    def __call__(self, done: int, total: int, grasp) -> None:
        self.valid += grasp.valid
        filled = round(self.width * done / total)
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r[{bar}] {done}/{total} samples, {self.valid} valid")
        self.stream.flush()

    def close(self) -> None:
        self.stream.write("\n")
        self.stream.flush()


def _verdict(grasp) -> str:
    """``valid``, ``collides`` or ``no contact`` (collision-free, a surface not touching), with
    ``=N`` for a duplicate of the grasp ranked N."""
    verdict = "valid" if grasp.valid else "collides" if not grasp.collision_free else "no contact"
    return verdict if grasp.duplicate_of is None else f"{verdict} ={grasp.duplicate_of}"


def _contact_cell(grasp) -> str:
    """The share of each contact surface's points touching the object, percent, in surface
    order, e.g. ``42/38``: 0 only for a surface that touches nowhere, else at least 1."""
    return "/".join(str(max(1, round(100 * share)) if share > 0 else 0)
                    for share in grasp.fit.surface_contact.values())


def _summary(result, top: int) -> str:
    shown = result.grasps[:top]
    surfaces = list(shown[0].fit.surface_contact) if shown else []
    width = max([10] + [len(_contact_cell(g)) for g in shown])
    head = (f"{'rank':>4}  {'grasp':<14} {'dist mm':>8} {'misalign deg':>12} {'clear mm':>9}  "
            f"{'contact %':<{width}}  {'position (m)':<26} joints")
    lines = [f"{result.gripper} on {result.object}, sampler {result.sampler}, seed {result.seed}"]
    if surfaces:
        lines.append(f"contact %: share of each surface's points touching the object "
                     f"({'/'.join(surfaces)})")
    if any(g.duplicate_of is not None for g in shown):
        lines.append("=N: the same grasp as the one ranked N (duplicate_of), within "
                     f"{result.diversity.distance * 1e3:g} mm and "
                     f"{math.degrees(result.diversity.angle):g} deg about the TCP")
    lines.append(head)
    for rank, g in enumerate(shown, start=1):
        p = g.T_object_gripper[:3, 3]
        joints = " ".join(f"{k}={v:.4g}" for k, v in g.joints.items())
        lines.append(
            f"{rank:>4}  {_verdict(g):<14} {g.fit.mean_distance * 1e3:>8.3f} "
            f"{math.degrees(g.fit.normal_misalignment):>12.2f} {g.collision.clearance * 1e3:>9.2f}  "
            f"{_contact_cell(g):<{width}}  {p[0]:+.4f} {p[1]:+.4f} {p[2]:+.4f}     {joints}"
        )
    return "\n".join(lines)


def _cmd_compile(args: argparse.Namespace) -> int:
    from .warming import warm_up

    seconds = warm_up(progress=None if args.quiet else _compile_progress)
    if not args.quiet:
        print(f"isf: kernels compiled or loaded in {seconds:.1f} s", file=sys.stderr)
    return EXIT_OK
