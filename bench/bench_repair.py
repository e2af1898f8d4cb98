"""CPU time of the collision repair (`isf.repair.clearance`) on the fits that collide in real plans.

Two steps, so that two versions of isf (or two repair settings, ``repair_settings.py``) can
repair the same fits:

* ``--collect CORPUS.pkl``: runs 60-sample plans (regret sampler) and stores every fit the
  planner hands to the repair, with the repair's answer. ``--corpus`` picks the plans:
  ``first`` (default; seeds 0..4): the paper gripper on the 2000-point Stanford bunny, the
  three-finger and Allegro hands (tagged as ``bench_hands.py`` does) on the YCB banana and
  tomato soup can (2000 points; needs the YCB folder); ``held-out`` (seeds 5..8): the duck, and
  the hands on the YCB mustard bottle and power drill; ``table-i`` (seeds 10..15): the paper
  gripper on the six objects of ``table1.py``. ``--repair KEY=VALUE,...`` sets the planner's
  repair parameters (the fits it collects depend on them, since the sampler learns from every
  outcome);
* ``CORPUS.pkl`` alone: builds one ``ClearanceRepair`` per configuration (after
  ``isf.warming.warm_up()``) and repairs every stored fit; reports the CPU time per repair
  (process time; median over ``--repeats`` passes), the set-up time (the first build in the
  run, whose caches are warm where an earlier configuration has the same gripper or mesh, then
  a build again), and how many repairs differ from the stored answers (pose, joints, depths
  or step count not bit-identical).

Run from the repository root, e.g. ``python bench/bench_repair.py --collect /tmp/corpus.pkl``,
then ``PYTHONPATH=<another checkout> python bench/bench_repair.py /tmp/corpus.pkl``.
The corpus is data: keep it out of the repository.
"""

from __future__ import annotations

import _common

import pickle
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import isf
from isf import assets
from isf.repair import clearance
from isf.warming import warm_up
from isf.planning._working_surface import resolve_spacing, working_surface

SAMPLES, MAX_POINTS = 60, 2000


CONFIGURATIONS = {  # name: (gripper, object); the paper gripper's objects scaled to it
    "paper-parallel/bunny": ("paper-parallel", "bunny"),
    "paper-parallel/duck": ("paper-parallel", "duck"),
    "paper-parallel/dragon": ("paper-parallel", "dragon"),
    "paper-parallel/banana": ("paper-parallel", "ycb:Banana"),
    "paper-parallel/scissors": ("paper-parallel", "ycb:Scissors"),
    "paper-parallel/drill": ("paper-parallel", "ycb:PowerDrill"),
    "three-finger/banana": ("three-finger", "ycb:Banana"),
    "three-finger/soup can": ("three-finger", "ycb:TomatoSoupCan"),
    "three-finger/mustard": ("three-finger", "ycb:MustardBottle"),
    "three-finger/drill": ("three-finger", "ycb:PowerDrill"),
    "allegro/banana": ("allegro", "ycb:Banana"),
    "allegro/soup can": ("allegro", "ycb:TomatoSoupCan"),
    "allegro/mustard": ("allegro", "ycb:MustardBottle"),
    "allegro/drill": ("allegro", "ycb:PowerDrill"),
}

CORPORA = {  # --corpus: the configurations planned and the seeds of their plans
    "first": (("paper-parallel/bunny", "three-finger/banana", "three-finger/soup can",
               "allegro/banana", "allegro/soup can"), range(5)),
    "held-out": (("paper-parallel/duck", "three-finger/mustard", "three-finger/drill",
                  "allegro/mustard", "allegro/drill"), range(5, 9)),
    "table-i": (tuple(name for name in CONFIGURATIONS if name.startswith("paper-parallel/")),
                range(10, 16)),
}


def configurations(names=None) -> dict[str, tuple[isf.Gripper, isf.ObjectSurface]]:
    """Gripper and object of the configurations ``names`` (default: the first corpus's), by
    name; each gripper and object is built once."""
    import bench_hands

    names = CORPORA["first"][0] if names is None else names
    grippers, objects, out = {}, {}, {}
    for name in names:
        gripper_name, object_name = CONFIGURATIONS[name]
        if gripper_name not in grippers:
            grippers[gripper_name] = (
                bench_hands.tagged_allegro(Path(tempfile.mkdtemp())) if gripper_name == "allegro"
                else isf.load_gripper(gripper_name))
        key = (gripper_name == "paper-parallel", object_name)
        if key not in objects:
            objects[key] = (
                _common.scaled_benchmark_object(object_name, max_points=MAX_POINTS)[0] if key[0]
                else isf.load_object(assets.benchmark_object(object_name).path,
                                     max_points=MAX_POINTS))
        out[name] = (grippers[gripper_name], objects[key])
    return out


def collect(path: str, corpus_name: str = "first",
            repair: isf.RepairConfig | None = None) -> None:
    """Plan the configurations of corpus ``corpus_name`` (repairing with ``repair``, default
    ``RepairConfig()``) and store the fits the planner repairs, with the answers."""
    names, seeds = CORPORA[corpus_name]
    corpus, original = {}, clearance.ClearanceRepair.repair
    for name, (gripper, obj) in configurations(names).items():
        cases = corpus.setdefault(name, [])

        def recording(self, T, q, **kwargs):
            out = original(self, T, q, **kwargs)
            cases.append((np.array(T), np.array(q), kwargs, tuple(out)))  # noqa: B023 (this case's list)
            return out

        clearance.ClearanceRepair.repair = recording
        try:
            for seed in seeds:
                isf.plan(gripper, obj, samples=SAMPLES, seed=seed,
                         repair_collisions=repair or True)
        finally:
            clearance.ClearanceRepair.repair = original
        print(f"# {name}: {len(cases)} repairs in {len(seeds)} plans", flush=True)
    Path(path).write_bytes(pickle.dumps(corpus))


def stored_configurations(path: str):
    """Every configuration of the corpus file ``path`` that has stored fits: ``(name, gripper,
    object as isf.plan fits it (its working surface), fits)``."""
    corpus = pickle.loads(Path(path).read_bytes())
    for name, (gripper, obj) in configurations(list(corpus)).items():
        if corpus[name]:
            yield name, gripper, working_surface(obj, resolve_spacing("auto", gripper)), corpus[name]


def same(a, b) -> bool:
    """Whether two repair answers (as tuples) are bit-identical."""
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def replay(path: str, repeats: int) -> None:
    """Repair the stored fits with this isf; print times and differences."""
    warm_up()
    print("| configuration | repairs | ms per repair, median (min-max) | set-up ms, first / "
          "again | differing |\n|---|---|---|---|---|")
    for name, gripper, obj, cases in stored_configurations(path):
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
    parser.add_argument("--corpus", dest="corpus_name", choices=sorted(CORPORA), default="first",
                        help="with --collect: which plans (default first)")
    parser.add_argument("--repair", default=None, metavar="KEY=VALUE,...",
                        help="with --collect: the planner's repair parameters (isf.RepairConfig; "
                             "default: its defaults)")
    args = parser.parse_args()
    if args.collect:
        repair = None if args.repair is None else _common.parse_config(
            parser, args.repair, "--repair", isf.RepairConfig)
        collect(args.corpus, args.corpus_name, repair)
    else:
        replay(args.corpus, 1 if args.quick else args.repeats)


if __name__ == "__main__":
    main()
