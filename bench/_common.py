"""Shared helpers of the benchmark scripts in ``bench/``.

Import this module FIRST in a benchmark script (before numpy, scipy, isf or open3d): it pins
OpenMP/BLAS to one thread through the environment, which those libraries read only once, when
they are loaded, and restricts the process to one CPU (Open3D's TBB pool ignores the
variables; ``ISF_BENCH_CPU=none`` turns pinning off, ``ISF_BENCH_CPU=k`` picks CPU k). A
variable the caller already set is kept (so ``OMP_NUM_THREADS=2 python bench/...`` measures two
threads), and :func:`machine_description` reports the values in force.

Helpers:

* :func:`time_calls` and :func:`run_repeats` / :class:`Timing`: median-of-N timing with the
  spread, and a time budget that stops repeating slow configurations (never below one run);
* :func:`markdown_table`, :func:`verdict`: result tables with the paper's figures and targets;
* :func:`machine_description`: CPU model, cores, load average, library versions, git state;
* :func:`import_open3d`: Open3D on machines without the system ``libusb`` (preloads the
  library shipped by the ``libusb-package`` wheel);
* :func:`scaled_benchmark_object`, :func:`object_with_points`: benchmark objects scaled "to fit
  the gripper" as the paper did, and sampled to a requested number of surface points;
* :func:`tagged_franka_hand`: the vendor Franka hand tagged by ``isf tag``'s suggestions;
* :func:`base_parser`, :class:`Deadline`: the ``--quick`` / ``--repeats`` / ``--budget`` /
  ``--deadline`` / ``--out`` options.

Run a script from the repository root, e.g. ``python bench/bench_iteration.py``.
"""

from __future__ import annotations

import os
import sys

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
for _name in THREAD_VARIABLES:
    os.environ.setdefault(_name, "1")


def _pin_to_one_cpu() -> str:
    """Restrict this process to one CPU unless ``ISF_BENCH_CPU=none``; return a note.

    The thread variables do not reach every library: Open3D 0.20 parallelises with TBB, which
    ignores ``OMP_NUM_THREADS`` and sizes its pool from the CPU affinity mask. Pinning (before
    those libraries load) makes "one core" true for all of them. ``ISF_BENCH_CPU=<k>`` picks
    the CPU; by default the highest-numbered usable one.
    """
    choice = os.environ.get("ISF_BENCH_CPU", "")
    if choice.lower() == "none" or not hasattr(os, "sched_setaffinity"):
        return "not pinned to a CPU"
    usable = sorted(os.sched_getaffinity(0))
    if choice and (not choice.isdigit() or int(choice) not in usable):
        raise SystemExit(f"ISF_BENCH_CPU={choice!r} is not a usable CPU: set it to one of "
                         f"{usable}, or to 'none' to run unpinned")
    cpu = int(choice) if choice else usable[-1]
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


_USABLE_AT_START = (os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity")
                    else set(range(os.cpu_count() or 1)))
PINNING = _pin_to_one_cpu()
_LATE = sorted({"numpy", "scipy", "open3d"} & set(sys.modules))
if _LATE:  # the variables above came too late for these libraries
    print(f"# warning: {_LATE} imported before bench/_common.py; thread pinning may not apply",
          file=sys.stderr)

import argparse
import ctypes
import dataclasses
import datetime
import hashlib
import importlib
import platform
import statistics
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: The paper's own figures (Fan et al., CASE 2018, section V-B and Table I; Matlab, 4 GHz i7).
PAPER = {
    "t_total_60": 2.33,  # s, average over the 9 objects of Table I, 60 samples each
    "ms_per_free": 64.4,  # ms per collision-free grasp (average)
    "free_of_60": 36.2,  # collision-free grasps of 60 samples (average)
    "vertices": 2022.1,  # average object size (vertices)
}

#: Targets of the issue "Real-time planning: a benchmark suite".
TARGETS = {
    "t_total_60_paper_s": 0.25,  # paper gripper, 60 samples
    "ms_per_free_paper": 8.0,  # paper gripper, per collision-free grasp
    "iteration_vs_open3d": 2.0,  # one ISF iteration / one Open3D point-to-plane ICP iteration
    "t_total_60_allegro_s": 1.5,
    "t_total_60_three_finger_s": 0.5,
    "growth_200k_2k": 1.5,  # t_total(200k points) / t_total(2k points)
}

#: Default --deadline of a script, seconds: keeps a default run near 3 minutes however slow
#: planning is (configurations run in priority order; later ones are skipped and marked).
DEFAULT_DEADLINE_S = 170.0

#: Middle bounding-box extent the paper-gripper benchmarks scale objects to (the gripper opens
#: 10-30 mm); the same rule as bench/table1.py.
PAPER_GRIPPER_MIDDLE_EXTENT = 0.025


# --------------------------------------------------------------------------- timing


@dataclass(frozen=True)
class Timing:
    """Repeated measurements of one quantity (seconds unless said otherwise).

    Attributes:
        values: every measurement, in run order.
        requested: how many were asked for (``len(values)`` is lower when a budget cut it).
    """

    values: tuple[float, ...]
    requested: int

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def median(self) -> float:
        return statistics.median(self.values)

    @property
    def low(self) -> float:
        return min(self.values)

    @property
    def high(self) -> float:
        return max(self.values)

    def spread(self, scale: float = 1.0, digits: int = 3) -> str:
        """``"median (min-max, n=N)"`` with values multiplied by ``scale``."""
        cut = "" if self.n == self.requested else f" of {self.requested} requested"
        med, low, high = (fmt(v * scale, digits) for v in (self.median, self.low, self.high))
        if self.n == 1:
            return f"{med} (n=1{cut})"
        return f"{med} ({low}-{high}, n={self.n}{cut})"


def use_cpus(count: int) -> str:
    """Let the process run on ``count`` of the CPUs usable at start (the pinned one first), for
    ``isf.plan(..., workers=count)``; returns a note. Does nothing when pinning is off
    (``ISF_BENCH_CPU=none``)."""
    if PINNING == "not pinned to a CPU" or not hasattr(os, "sched_setaffinity"):
        return PINNING
    chosen = os.environ.get("ISF_BENCH_CPU", "")
    first = int(chosen) if chosen.isdigit() else max(_USABLE_AT_START)
    cpus = [first] + sorted(set(_USABLE_AT_START) - {first}, reverse=True)
    os.sched_setaffinity(0, set(cpus[:count]))
    return f"on CPU(s) {sorted(os.sched_getaffinity(0))}"


@dataclass(frozen=True)
class Mode:
    """How ``isf.plan`` runs the samples: ``batch_size`` in lockstep in one thread, or one at a
    time on ``workers`` threads."""

    batch_size: int = 1
    workers: int = 1

    @property
    def label(self) -> str:
        return f"W={self.workers}" if self.workers > 1 else f"B={self.batch_size}"

    @classmethod
    def parse(cls, text: str) -> Mode:
        """``"8"``: batch size 8; ``"w2"``: two worker threads."""
        if text.lower().startswith("w") and text[1:].isdigit() and int(text[1:]) >= 1:
            return cls(workers=int(text[1:]))
        if text.isdigit() and int(text) >= 1:
            return cls(batch_size=int(text))
        raise ValueError(f"{text!r} is neither a batch size (8) nor a worker count (w2)")


def default_batch_size() -> int:
    """The ``batch_size`` that ``isf.plan`` uses when none is given."""
    import inspect

    import isf

    return int(inspect.signature(isf.plan).parameters["batch_size"].default)


def plan_once(gripper, obj, samples: int, seed: int, config=None, batch_size: int | None = None,
              sampler=None, repair_collisions=None, **plan_kwargs) -> dict:
    """One ``isf.plan``: wall and CPU time, stage times, counts, fit quality.

    Args:
        gripper, obj, samples, seed, config: passed to ``isf.plan``.
        batch_size: samples fitted in lockstep (None: ``isf.plan``'s default; 1: the paper's
            strictly sequential loop).
        sampler: a sampler name or instance; None (default): the regret bandit with every start
            on a cluster centre (``RegretSampler(com_share=0)``), as the speed figures of
            docs/benchmarks.md were measured.
        repair_collisions: passed to ``isf.plan`` (None: its default, on; False: the paper's
            Algorithm 3 without the collision repair; an ``isf.RepairConfig``: the repair with
            those parameters).
        **plan_kwargs: further keyword arguments of ``isf.plan`` (e.g. ``working_spacing``);
            ``rank`` defaults to ``"fit"`` and ``centring`` to False, as the speed figures of
            docs/benchmarks.md were measured (pass them for ``isf.plan``'s defaults).

    Returns:
        a dict of floats: ``t_total`` (``PlanStats.total_time``, s), ``cpu`` (process time around
        the call, s), ``setup``/``fit``/``collision`` (stage times, s), ``free`` and ``valid``
        (counts), ``per_free`` (s per collision-free grasp), ``error`` (mean
        ``FitResult.mean_distance`` of the collision-free grasps, m; NaN when none),
        ``error_full`` (the same grasps' contact points measured against every point of ``obj``,
        see :func:`surface_error`, m), ``surface_points`` (``PlanStats.surface_points``) and
        ``iterations`` (mean ISF iterations per sample).
    """
    import isf

    if sampler is None:
        from isf.samplers import RegretSampler

        sampler = RegretSampler(com_share=0)
    kwargs = {"rank": "fit", "centring": False, **plan_kwargs}
    if batch_size is not None:
        kwargs["batch_size"] = batch_size
    if repair_collisions is not None:
        kwargs["repair_collisions"] = repair_collisions
    cpu = time.process_time()
    result = isf.plan(gripper, obj, samples=samples, sampler=sampler, seed=seed, config=config,
                      **kwargs)
    cpu = time.process_time() - cpu
    s = result.stats
    free = result.collision_free_grasps()
    return {"t_total": s.total_time, "cpu": cpu, "setup": s.setup_time, "fit": s.fit_time,
            "collision": s.collision_time, "free": s.collision_free, "valid": s.valid,
            "per_free": s.total_time / s.collision_free if s.collision_free else float("inf"),
            "error": statistics.fmean(g.fit.mean_distance for g in free) if free else float("nan"),
            "error_full": (statistics.fmean(surface_error(g.fit, obj) for g in free) if free
                           else float("nan")),
            "surface_points": s.surface_points,
            "iterations": statistics.fmean(g.fit.iterations for g in result.grasps)}


def surface_error(fit, obj) -> float:
    """Mean absolute point-to-plane distance of a fit's matched contact points
    (``FitResult.contact_points``, object frame) to ``obj``'s nearest point and its normal, m:
    the fit error measured against the whole surface even when the planner matched against a
    thinned one (``PlanStats.surface_points``)."""
    import numpy as np

    if not len(fit.contact_points):
        return float("nan")
    _, nearest = obj.nearest(fit.contact_points)
    offsets = fit.contact_points - obj.points[nearest]
    return float(np.abs(np.einsum("ij,ij->i", offsets, obj.normals[nearest])).mean())


def time_calls(fn: Callable[[], object], calls: int, warmup: int = 1) -> tuple[float, float]:
    """Median wall time and median process CPU time of one call of ``fn``, seconds.

    Each of the ``calls`` calls is timed on its own (``time.perf_counter`` and
    ``time.process_time``; right for calls >= ~10 us). On a shared machine the wall time also
    counts waiting for a core; the CPU time of single-threaded code does not.
    """
    for _ in range(warmup):
        fn()
    wall, cpu = [], []
    for _ in range(calls):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu)


def run_repeats(fn: Callable[[int], dict], repeats: int, budget_s: float | None,
                catch: tuple[type[BaseException], ...] = ()) -> tuple[list[dict], list[str]]:
    """Call ``fn(seed)`` for seeds 0, 1, ... and collect its result dicts.

    Stops early, after at least one run, once the runs took ``budget_s`` seconds in all, so a
    slow configuration cannot stall a benchmark; the tables show how many runs each median has.

    Returns:
        (results of the runs that succeeded, ``"seed N: ErrorClass: message"`` for each run that
        raised one of ``catch``; a benchmark reports failures instead of dying on them).
    """
    out, failed, spent = [], [], 0.0
    for seed in range(repeats):
        t0 = time.perf_counter()
        try:
            out.append(fn(seed))
        except catch as err:
            failed.append(f"seed {seed}: {type(err).__name__}: {err}")
            print(f"#   run with seed {seed} failed: {failed[-1]}", flush=True)
        spent += time.perf_counter() - t0
        if budget_s is not None and spent >= budget_s:
            break
    return out, failed


def _nan_median(values: Sequence[float]) -> float:
    """Median ignoring NaN (NaN when every value is NaN)."""
    finite = [v for v in values if v == v]
    return float(statistics.median(finite)) if finite else float("nan")


def median_row(runs: Sequence[dict], failed: Sequence[str], requested: int,
               key: str = "t_total") -> dict:
    """Medians of every field of ``runs``, the :class:`Timing` of ``key`` as ``"timing"`` and the
    failures as ``"failed"``; only ``{"failed": [...]}`` when no run succeeded."""
    if not runs:
        return {"failed": list(failed)}
    row = {k: _nan_median([float(r[k]) for r in runs]) for k in runs[0]}
    row["timing"], row["failed"] = timing(runs, key, requested), list(failed)
    return row


def timing_cell(row: dict, scale: float = 1.0) -> str:
    """The ``Timing`` of a :func:`median_row` as table text, with failed runs counted."""
    if "timing" not in row:
        kinds = sorted({f.split(":")[1].strip() for f in row["failed"]})
        return f"failed (all {len(row['failed'])} runs: {', '.join(kinds)})"
    text = row["timing"].spread(scale)
    return text + (f"; {len(row['failed'])} run(s) failed" if row["failed"] else "")


def failure_notes(rows: Sequence[tuple[str, dict]]) -> list[str]:
    """A report paragraph quoting every failed run (empty when none failed)."""
    lines = [f"- {label}: {f}" for label, row in rows for f in row.get("failed", ())]
    return ["Failed runs (the library raised; not counted in the medians):\n\n"
            + "\n".join(lines)] if lines else []


def timing(rows: Sequence[dict], key: str, requested: int) -> Timing:
    """A :class:`Timing` of ``row[key]`` over result dicts from :func:`run_repeats`."""
    return Timing(tuple(float(r[key]) for r in rows), requested)


# --------------------------------------------------------------------------- tables


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table; cells are converted with ``str``."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def verdict(value: float, target: float) -> str:
    """``"yes"`` when ``value <= target``, else ``"no (N x the target)"``."""
    if value != value or value == float("inf"):
        return "no (no finite value)"
    if value <= target:
        return "yes"
    return f"no ({value / target:.1f}x the target)"


def fmt(value: float, digits: int = 3) -> str:
    """``value`` with ``digits`` significant digits; ``inf`` and ``nan`` as ``-``."""
    if value != value or value in (float("inf"), float("-inf")):
        return "-"
    if abs(value) >= 10**digits:
        return f"{value:.0f}"
    return f"{value:.{digits}g}"


def mean_and_error(differences: Sequence[float]) -> str:
    """Paired differences as ``"+M.MM +- E.EE"``: their mean and its standard error (``nan``
    for a single pair; ``"-"`` for none)."""
    values = list(differences)
    if not values:
        return "-"
    error = statistics.stdev(values) / len(values) ** 0.5 if len(values) > 1 else float("nan")
    return f"{statistics.fmean(values):+.2f} +- {error:.2f}"


def parse_config(parser, text: str, option: str, cls: type):
    """A parameter dataclass ``cls`` (``isf.FitConfig``, ``isf.RepairConfig``) from
    ``KEY=VALUE,...`` (:func:`isf.config.config_from_text`); a bad key or value is a parser
    error that names ``option``."""
    import isf
    from isf.config import config_from_text

    words = dict(item.partition("=")[::2] for item in text.split(","))
    try:
        return config_from_text(cls, words)
    except isf.ConfigError as err:
        parser.error(f"{option}: {err}")


def changed_fields(config) -> str:
    """The fields of ``config`` (a parameter dataclass) that differ from its defaults, as
    ``KEY=VALUE,...``."""
    default = type(config)()
    return ",".join(f"{f.name}={getattr(config, f.name)}" for f in dataclasses.fields(config)
                    if getattr(config, f.name) != getattr(default, f.name))


# --------------------------------------------------------------------------- machine


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (or platform's guess elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git(*args: str) -> str:
    try:
        proc = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True,
                              timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return proc.stdout.strip() if proc.returncode == 0 else ""


_START_FINGERPRINT: str | None = None


def source_fingerprint() -> str:
    """Short hash of the package's sources (``isf/**/*.py``), to tie results to the exact code
    measured (the package is edited between commits)."""
    digest = hashlib.sha256()
    for path in sorted((REPO / "isf").rglob("*.py")):
        digest.update(path.relative_to(REPO).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def machine_description() -> str:
    """One markdown paragraph: date, CPU, cores, load, threads, versions, git state. Compiles
    (or loads) isf's kernels first, so that no timing includes it (the paragraph says how long)."""
    import numba
    import numpy
    import scipy

    import isf
    from isf.warming import warm_up

    kernels = warm_up()

    load = " / ".join(f"{v:.2f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    usable = len(_USABLE_AT_START)
    global _START_FINGERPRINT
    _START_FINGERPRINT = source_fingerprint()
    commit = _git("rev-parse", "--short", "HEAD") or "?"
    dirty = _git("status", "--porcelain", "--", "isf")
    threads = ", ".join(f"{v}={os.environ.get(v)}" for v in THREAD_VARIABLES) + f"; {PINNING}"
    return (
        f"{datetime.datetime.now().isoformat(timespec='seconds')}; CPU: {cpu_model()}, "
        f"{os.cpu_count()} logical cores ({usable} usable); load average (1/5/15 min) at start: "
        f"{load}; {threads}; Python {platform.python_version()}, numpy {numpy.__version__}, "
        f"scipy {scipy.__version__}, numba {numba.__version__} (isf's kernels compiled or "
        f"loaded in {kernels:.1f} s before timing), isf {isf.__version__} at git {commit}"
        f"{' with uncommitted changes in isf/' if dirty else ''} (isf/**/*.py sha256 "
        f"{_START_FINGERPRINT})."
    )


def load_average() -> str:
    """The 1-minute load average now, for end-of-run notes."""
    return f"{os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "?"


# --------------------------------------------------------------------------- open3d


def import_open3d():
    """Return the ``open3d`` module, quiet, or None when it is not installed.

    Open3D's wheel links against ``libusb-1.0.so.0``, which slim machines lack; the
    ``libusb-package`` wheel ships that library, and loading it globally first satisfies the
    link. Thread count: Open3D's OpenMP reads ``OMP_NUM_THREADS`` (set by this module).
    """
    try:
        o3d = importlib.import_module("open3d")
    except ImportError as err:
        if "libusb" not in str(err):
            return None
        try:
            import libusb_package
        except ImportError:
            return None
        ctypes.CDLL(str(libusb_package.get_library_path()), mode=ctypes.RTLD_GLOBAL)
        o3d = importlib.import_module("open3d")
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    return o3d


# --------------------------------------------------------------------------- grippers


def tagged_franka_hand(folder):
    """The vendor Franka hand (``isf.assets.vendor_gripper("franka-hand")``) tagged as a user
    tags it: ``isf tag`` with every suggestion (a contact surface on the distal half of each
    finger's inner face, the approach, the TCP), written into ``folder`` and loaded. It is the
    gripper of the learned sampler's bundled ``franka-hand`` model, made by the plugin's
    ``isf_sampler_learned.bundled.tagged_franka_hand`` (the plugin is installed with the test
    extras)."""
    from isf_sampler_learned.bundled import tagged_franka_hand as tagged

    return tagged(folder)


# --------------------------------------------------------------------------- objects


def scaled_benchmark_object(name: str, middle_extent: float = PAPER_GRIPPER_MIDDLE_EXTENT,
                            **load_kwargs):
    """Load benchmark object ``name`` (see ``isf.assets.benchmark_objects``) scaled uniformly so
    the middle of its three bounding-box extents is ``middle_extent`` metres (the paper scaled
    objects "to fit into the gripper range").

    Args:
        name: a benchmark object name, e.g. ``"bunny"`` or ``"ycb:Banana"``.
        middle_extent: target middle extent, metres.
        **load_kwargs: passed to ``isf.load_object`` (``max_points``, ``voxel_size`` ...).

    Returns:
        (ObjectSurface, scale): the surface and the factor applied to the file's coordinates.
    """
    import numpy as np
    import trimesh

    import isf
    from isf import assets

    asset = assets.benchmark_object(name)
    mesh = trimesh.load(asset.path, force="mesh", process=False)
    extents = np.sort(np.ptp(np.asarray(mesh.vertices), axis=0) * asset.scale)
    scale = asset.scale * middle_extent / extents[1]
    load_kwargs.setdefault("name", name)
    return isf.load_object(asset.path, scale=scale, **load_kwargs), scale


def object_with_points(path, scale: float, n_points: int, name: str, tolerance: float = 0.1,
                       attempts: int = 8):
    """Load a mesh with a voxel size searched so it has ``n_points`` (+-``tolerance``) points.

    The count of a surface sampled at voxel size h scales as 1/h^2, so h is refined with
    ``h <- h * sqrt(n(h) / n_points)``. Returns the closest surface found.
    """
    import isf

    best, h = None, None
    for _ in range(attempts):
        kwargs = {"voxel_size": h} if h is not None else {}
        obj = isf.load_object(path, scale=scale, name=f"{name} ({n_points} pts)", **kwargs)
        if best is None or abs(obj.n_points - n_points) < abs(best.n_points - n_points):
            best = obj
        if abs(obj.n_points - n_points) <= tolerance * n_points:
            break
        h = obj.spacing * (obj.n_points / n_points) ** 0.5
    return best


# --------------------------------------------------------------------------- CLI


def base_parser(description: str, repeats: int, budget: float) -> argparse.ArgumentParser:
    """An argument parser with the options every benchmark script shares."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true",
                        help="a smaller, faster run (fewer configurations and repeats)")
    parser.add_argument("--repeats", type=int, default=repeats,
                        help=f"runs per configuration; medians are reported (default {repeats})")
    parser.add_argument("--budget", type=float, default=budget,
                        help="seconds per configuration after which no further repeat starts "
                             f"(at least one run always happens; default {budget:g}, 0 = none)")
    parser.add_argument("--deadline", type=float, default=DEFAULT_DEADLINE_S,
                        help="seconds after which configurations not yet started are skipped "
                             "and marked so (they run in priority order; default "
                             f"{DEFAULT_DEADLINE_S:g}, 0 = none)")
    parser.add_argument("--out", default=None,
                        help="also write the markdown report to this file")
    return parser


class Deadline:
    """Wall-clock limit of a whole script (``seconds`` None or <= 0: no limit)."""

    def __init__(self, seconds: float | None):
        self.seconds = seconds if seconds and seconds > 0 else None
        self.start = time.perf_counter()
        self.skipped: list[str] = []

    def allows(self, what: str) -> bool:
        """True if ``what`` may start; otherwise records it as skipped."""
        if self.seconds is None or time.perf_counter() - self.start < self.seconds:
            return True
        self.skipped.append(what)
        print(f"# deadline of {self.seconds:g} s passed: skipping {what}", flush=True)
        return False

    def note(self) -> list[str]:
        """A report line naming what was skipped (empty if nothing was)."""
        if not self.skipped:
            return []
        return [f"Skipped after the --deadline of {self.seconds:g} s: "
                + "; ".join(self.skipped) + "."]


def budget_or_none(args: argparse.Namespace) -> float | None:
    return args.budget if args.budget and args.budget > 0 else None


def command_line() -> str:
    """The command that ran this script, for the report."""
    return "python " + " ".join([os.path.relpath(sys.argv[0], REPO), *sys.argv[1:]])


#: Printed in every report: how to read wall times measured on a shared machine.
NOISE_NOTE = ("Wall times on a shared machine are noisy: they include waiting for a core while "
              "other jobs run (compare the load averages at the start and the end); the process "
              "CPU time beside them does not, so prefer it, and the ratios measured in the same "
              "process, when comparing figures.")


def finish(title: str, sections: Sequence[str], started: float, header: str,
           out: str | None) -> str:
    """Print (and optionally write) the report: title, machine note, sections, run time."""
    changed = _START_FINGERPRINT is not None and source_fingerprint() != _START_FINGERPRINT
    warning = []
    if changed:
        warning.append(f"Note: isf's sources changed on disk during the run (sha256 now "
                       f"{source_fingerprint()}); the process measured the modules it imported "
                       "at start-up.")
    text = "\n\n".join([
        f"## {title}",
        f"Command: `{command_line()}`",
        f"Machine: {header}",
        NOISE_NOTE,
        *sections,
        *warning,
        f"Wall time of the whole script: {time.perf_counter() - started:.0f} s; "
        f"1-min load average at the end: {load_average()}.",
    ]) + "\n"
    print(text)
    if out:
        Path(out).write_text(text)
    return text
