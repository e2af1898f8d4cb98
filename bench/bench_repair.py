"""CPU time of the collision repair (`isf.clearance`) on the fits that collide in real plans.

Two steps, so that two versions of isf can repair the same fits:

* ``--collect CORPUS.pkl``: runs 60-sample plans (regret sampler, seeds 0..4) of the paper
  gripper on the 2000-point Stanford bunny and of the three-finger and Allegro hands (tagged as
  ``bench_hands.py`` does) on the YCB banana and tomato soup can (2000 points; needs the YCB
  folder), and stores every fit the planner hands to the repair, with the repair's answer;
* ``CORPUS.pkl`` alone: builds one ``ClearanceRepair`` per configuration (after
  ``isf.compiled.warm_up()``) and repairs every stored fit; reports the CPU time per repair
  (process time; median over ``--repeats`` passes), the set-up time (the first build in the
  run, whose caches are warm where an earlier configuration has the same gripper or mesh, then
  a build again), and how many repairs differ from the stored answers (pose, joints, depths
  or step count not bit-identical).

Run from the repository root, e.g. ``python bench/bench_repair.py --collect /tmp/corpus.pkl``,
then ``PYTHONPATH=<another checkout> python bench/bench_repair.py /tmp/corpus.pkl``.
The corpus is data: keep it out of the repository.
"""

from __future__ import annotations

import _common  # noqa: I001  (first: pins BLAS/OpenMP threads before numpy is imported)

import pickle  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import isf  # noqa: E402
from isf import assets, clearance  # noqa: E402
from isf.compiled import warm_up  # noqa: E402
from isf.working_surface import resolve_spacing, working_surface  # noqa: E402

SAMPLES, SEEDS, MAX_POINTS = 60, range(5), 2000


def configurations() -> dict[str, tuple[isf.Gripper, isf.ObjectSurface]]:
    """Gripper and object of every configuration, by name."""
    import bench_hands

    allegro = bench_hands.tagged_allegro(Path(tempfile.mkdtemp()))
    three = isf.load_gripper("three-finger")
    ycb = {name: isf.load_object(assets.benchmark_object(f"ycb:{name}").path,
                                 max_points=MAX_POINTS) for name in ("Banana", "TomatoSoupCan")}
    bunny, _ = _common.scaled_benchmark_object("bunny", max_points=MAX_POINTS)
    return {"paper-parallel/bunny": (isf.load_gripper("paper-parallel"), bunny),
            "three-finger/banana": (three, ycb["Banana"]),
            "three-finger/soup can": (three, ycb["TomatoSoupCan"]),
            "allegro/banana": (allegro, ycb["Banana"]),
            "allegro/soup can": (allegro, ycb["TomatoSoupCan"])}


def collect(path: str) -> None:
    """Plan every configuration and store the fits the planner repairs, with the answers."""
    corpus, repair = {}, clearance.ClearanceRepair.repair
    for name, (gripper, obj) in configurations().items():
        cases = corpus.setdefault(name, [])

        def recording(self, T, q, **kwargs):
            out = repair(self, T, q, **kwargs)
            cases.append((np.array(T), np.array(q), kwargs, tuple(out)))
            return out

        clearance.ClearanceRepair.repair = recording
        try:
            for seed in SEEDS:
                isf.plan(gripper, obj, samples=SAMPLES, seed=seed)
        finally:
            clearance.ClearanceRepair.repair = repair
        print(f"# {name}: {len(cases)} repairs in {len(SEEDS)} plans", flush=True)
    Path(path).write_bytes(pickle.dumps(corpus))


def same(a, b) -> bool:
    """Whether two repair answers (as tuples) are bit-identical."""
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def replay(path: str, repeats: int) -> None:
    """Repair the stored fits with this isf; print times and differences."""
    corpus = pickle.loads(Path(path).read_bytes())
    warm_up()
    print("| configuration | repairs | ms per repair, median (min-max) | set-up ms, first / "
          "again | differing |\n|---|---|---|---|---|")
    for name, (gripper, obj) in configurations().items():
        cases = corpus.get(name)
        if not cases:
            continue
        obj = working_surface(obj, resolve_spacing("auto", gripper))  # as isf.plan does
        start = time.process_time()
        repairer = clearance.ClearanceRepair(gripper, obj)
        first = time.process_time() - start
        start = time.process_time()
        clearance.ClearanceRepair(gripper, obj)
        again = time.process_time() - start
        repairer.repair(*cases[0][:2], **cases[0][2])
        times, outs = [], []
        for _ in range(repeats):
            start = time.process_time()
            outs = [repairer.repair(T, q, **kwargs) for T, q, kwargs, _ in cases]
            times.append((time.process_time() - start) / len(cases))
        differing = sum(not same(tuple(out), case[3]) for out, case in zip(outs, cases))
        ms = [1e3 * t for t in times]
        print(f"| {name} | {len(cases)} | {statistics.median(ms):.1f} "
              f"({min(ms):.1f}-{max(ms):.1f}) | {1e3 * first:.0f} / {1e3 * again:.1f} "
              f"| {differing} |", flush=True)


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=5, budget=0.0)
    parser.add_argument("corpus", help="the corpus file (written with --collect)")
    parser.add_argument("--collect", action="store_true",
                        help="plan and store the fits the repair gets, instead of timing")
    args = parser.parse_args()
    if args.collect:
        collect(args.corpus)
    else:
        replay(args.corpus, 1 if args.quick else args.repeats)


if __name__ == "__main__":
    main()
