"""Before/after of two versions of isf in one process: the same plans, alternating, paired by seed.

The shared machines these benchmarks run on drift by tens of per cent within an hour, so two
versions timed in separate runs cannot be told apart to a few per cent. This script extracts isf
at ``--base`` (a git revision) as a second package, ``isf_base``, and plans the same (object,
seed) pairs with it and with the working tree's isf, alternating which goes first. Per gripper
it reports the median ``t_total`` of each (process CPU time in one thread, wall time with
``--workers``), the median and mean of the paired ratios base / current, whether the two
versions found the same number of collision-free grasps in every pair, and, for a change that
alters results, each version's mean collision-free count per plan and mean fitting error of the
collision-free grasps (``FitResult.mean_distance``, over those with pairs), with the paired
difference of the counts (mean and standard error over the pairs).

The base is extracted once per revision into the temporary folder (``isf-base-<sha>``), where
numba caches its kernels: the first run compiles them (about two minutes). Objects: the paper
gripper plans the bunny, duck and dragon scaled to it (2000 points); the hands plan the YCB
banana and mustard bottle (built-in shapes when the YCB folder is missing). Every plan uses the
default planner with a regret sampler made by its own version.

Run from the repository root:
    python bench/ab_versions.py --base d2161d0 [--grippers paper,three,allegro] [--seeds 4]
        [--first-seed 0] [--workers 2]
"""

from __future__ import annotations

import importlib
import io
import math
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import _common  # before numpy and isf: pins BLAS/OpenMP threads (see _common)
import bench_hands

import isf
from isf import assets

PAPER_OBJECTS = ("bunny", "duck", "dragon")
GRIPPERS = ("paper", "three", "allegro")
_ABSOLUTE_IMPORT = re.compile(r"^(\s*)(from|import) isf(?=[. ])", re.MULTILINE)


def warm_up(package) -> None:
    """Compile or load the kernels of one version (``warming.warm_up``, or ``compiled.warm_up``
    in versions before the subpackage layout)."""
    try:
        module = importlib.import_module(f"{package.__name__}.warming")
    except ImportError:
        module = importlib.import_module(f"{package.__name__}.compiled")
    module.warm_up()


def base_package(revision: str):
    """isf at ``revision``, imported as the package ``isf_base`` (extracted once per revision)."""
    try:
        sha = subprocess.run(["git", "rev-parse", "--verify", f"{revision}^{{commit}}"],
                             cwd=_common.REPO, capture_output=True, text=True,
                             check=True).stdout.strip()
        archive = subprocess.run(["git", "archive", sha, "isf", "grippers"], cwd=_common.REPO,
                                 capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        raise SystemExit(f"--base {revision!r} is not a revision of this repository: give a "
                         "commit, tag or branch (e.g. HEAD~3)") from None
    folder = Path(tempfile.gettempdir()) / f"isf-base-{sha[:12]}"
    if not (folder / "isf_base").is_dir():
        staging = Path(tempfile.mkdtemp(prefix="isf-base-"))
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(staging, filter="data")
        for source in (staging / "isf").rglob("*.py"):  # older versions import isf absolutely
            source.write_text(_ABSOLUTE_IMPORT.sub(r"\1\2 isf_base", source.read_text()))
        (staging / "isf").rename(staging / "isf_base")
        staging.rename(folder)  # the bundled grippers sit beside the package, as in a checkout
    sys.path.insert(0, str(folder))
    return importlib.import_module("isf_base"), sha[:12]


def setup(package, gripper: str) -> tuple[object, list]:
    """The gripper and the objects of ``gripper`` built by ``package`` (isf or isf_base)."""
    if gripper == "paper":
        objects = []
        for name in PAPER_OBJECTS:
            _, scale = _common.scaled_benchmark_object(name, max_points=2000)
            objects.append(package.load_object(assets.benchmark_object(name).path, scale=scale,
                                               max_points=2000, name=name))
        return package.load_gripper("paper-parallel"), objects
    try:
        ycb = set(bench_hands.YCB_OBJECTS[:2]) <= set(assets.benchmark_objects("ycb"))
    except isf.ISFError:
        ycb = False
    objects = ([package.open_object(f"asset:{n}", max_points=bench_hands.MAX_POINTS)
                for n in bench_hands.YCB_OBJECTS[:2]] if ycb else
               [package.open_object(s, scale=bench_hands.SHAPE_SCALE,
                                    max_points=bench_hands.MAX_POINTS)
                for s in bench_hands.SHAPE_OBJECTS[:2]])
    if gripper == "three":
        return package.load_gripper("three-finger"), objects
    folder = Path(tempfile.mkdtemp())
    bench_hands.tagged_allegro(folder)  # writes the tagged URDF
    source = assets.vendor_gripper(bench_hands.ALLEGRO)
    dirs = bench_hands._package_dirs(source, source.read_text())
    return package.load_gripper(folder / f"{bench_hands.ALLEGRO}-isf.urdf",
                                package_dirs=dirs), objects


def plan(package, gripper, obj, seed: int, workers: int) -> tuple[float, int, list[float]]:
    """``(seconds, collision-free grasps, their fitting errors (m))`` of one plan: CPU time in
    one thread, else wall."""
    sampler = importlib.import_module(f"{package.__name__}.samplers.regret").RegretSampler()
    c0, t0 = time.process_time(), time.perf_counter()
    result = package.plan(gripper, obj, samples=60, seed=seed, workers=workers, sampler=sampler)
    seconds = time.perf_counter() - t0 if workers > 1 else time.process_time() - c0
    errors = [g.fit.mean_distance for g in result.grasps if g.collision_free]
    return seconds, len(errors), errors


def error_cell(errors: list[float]) -> str:
    """The mean fitting error (mm) of collision-free grasps with pairs, and how many had none
    (their ``mean_distance`` is infinite: no contact point matched the object)."""
    finite = [e for e in errors if math.isfinite(e)]
    cell = _common.fmt(1e3 * statistics.fmean(finite)) if finite else "-"
    return cell + (f" ({len(errors) - len(finite)} without pairs)" if len(finite) < len(errors) else "")


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("--base", required=True, help="the git revision to compare against")
    parser.add_argument("--grippers", default=",".join(GRIPPERS),
                        help="comma-separated: paper, three, allegro (default all)")
    parser.add_argument("--seeds", type=int, default=4, help="seeds per object (default 4)")
    parser.add_argument("--first-seed", type=int, default=0, help="the first seed (default 0)")
    parser.add_argument("--workers", type=int, default=1, help="worker threads (default 1)")
    args = parser.parse_args()
    grippers = args.grippers.split(",")
    if not set(grippers) <= set(GRIPPERS) or args.seeds < 1 or args.workers < 1:
        parser.error(f"--grippers takes {', '.join(GRIPPERS)}; --seeds and --workers must be >= 1")
    _common.use_cpus(args.workers)
    started, header = time.perf_counter(), _common.machine_description()
    base, sha = base_package(args.base)
    versions = {"base": base, "current": isf}
    for package in versions.values():
        warm_up(package)
    seeds = 1 if args.quick else args.seeds
    rows = []
    for name in grippers:
        setups = {v: setup(p, name) for v, p in versions.items()}
        for v, (gripper, objects) in setups.items():  # first plans build the memos
            plan(versions[v], gripper, objects[0], 99, args.workers)
        times, free, errors = ({v: [] for v in versions} for _ in range(3))
        agree = True
        for pair, (seed, k) in enumerate((s, k) for s in range(args.first_seed,
                                                                 args.first_seed + seeds)
                                         for k in range(len(setups["base"][1]))):
            counts = {}
            for v in (("base", "current") if pair % 2 == 0 else ("current", "base")):
                gripper, objects = setups[v]
                seconds, counts[v], fit_errors = plan(versions[v], gripper, objects[k], seed,
                                                      args.workers)
                times[v].append(seconds)
                free[v].append(counts[v])
                errors[v] += fit_errors
            agree = agree and counts["base"] == counts["current"]
        ratios = [b / c for b, c in zip(times["base"], times["current"])]
        gained = [c - b for b, c in zip(free["base"], free["current"])]
        rows.append([name, len(ratios), _common.fmt(statistics.median(times["base"])),
                     _common.fmt(statistics.median(times["current"])),
                     _common.fmt(statistics.median(ratios)), _common.fmt(statistics.fmean(ratios)),
                     "yes" if agree else "no",
                     *(f"{statistics.fmean(free[v]):.2f}" for v in versions),
                     _common.mean_and_error(gained),
                     *(error_cell(errors[v]) for v in versions)])
        print(f"# {name}: paired base / current {statistics.median(ratios):.3f}", flush=True)
    clock = "CPU" if args.workers == 1 else "wall"
    table = _common.markdown_table(
        ["gripper", "paired plans", f"base ({sha}): t_total ({clock}, s)",
         f"current: t_total ({clock}, s)", "base / current, median", "mean",
         "same collision-free counts", "collision-free per plan, base", "current",
         "current - base (mean +- s.e.)",
         "fit error (mm), base", "current"], rows)
    _common.finish(f"ab_versions: {sha} against the working tree, {args.workers} thread(s)",
                   [table], started, header, args.out)


if __name__ == "__main__":
    main()
