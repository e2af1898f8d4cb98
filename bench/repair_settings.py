"""Collision-repair settings compared: on the same colliding fits, and in whole plans (where
ISF settings can be compared too).

Each ``--setting NAME:KEY=VALUE,...`` is an ``isf.RepairConfig`` (its other fields default),
each ``--fit-setting NAME:KEY=VALUE,...`` (``plans`` only) an ``isf.FitConfig``; a NAME given
to both plans with both. The defaults (``RepairConfig()``, ``FitConfig()``: the paper's ISF
parameters) are always compared too, as ``default``. Two commands:

* ``corpus CORPUS.pkl``: the fits of a corpus (``bench/bench_repair.py --collect``) repaired
  with every setting and re-checked by the planner's collision checker
  (``isf.planning._evaluation.SampleJudge``: a repair counts only when that check passes). Per
  configuration and setting: the repairs that pass (and how many of them differ from the
  default's), the CPU time and steps of all repairs, and the mean point-to-plane distance of
  the repaired grasps (``isf.fitting.engine.score_fit``) over those that pass with every setting.
  Then, per setting and outcome (pass or fail with the default and with the setting): in the
  setting's first step, the most opposed pair of clearance-row normals within one geometry
  element (the median of its dot product; -1 means rows pushing one link opposite ways).
* ``plans``: 60-sample plans of one gripper (``--gripper paper`` on the objects of
  ``table1.py`` scaled to it, ``three`` or ``allegro`` on the YCB objects of
  ``bench_hands.py``), ``--objects N`` of them, seeds ``--seeds``, every setting on the same
  (object, seed) pairs in turn, one thread: collision-free and valid grasps per plan and their
  paired differences to the default (mean and standard error, the pairs higher and lower), the
  mean fit error of the collision-free grasps that touch the object and its paired difference,
  the ISF iterations per sample and the CPU time per plan; ``--on-table`` puts each object on
  a table (a plane through its lowest point).

Run from the repository root, e.g.::

    python bench/repair_settings.py corpus /tmp/corpus.pkl --setting old:max_rows=12,activation=0.008
    python bench/repair_settings.py plans --gripper three --objects 2 --seeds 0-7 \
        --setting old:max_rows=12,activation=0.008
    python bench/repair_settings.py plans --gripper paper --objects 6 --seeds 0-7 \
        --fit-setting loose:tolerance=0.016
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import _common  # before numpy and isf: pins BLAS/OpenMP threads (see _common)
import bench_hands
import numpy as np
from bench_repair import stored_configurations
from table1 import DEFAULT_OBJECTS

import isf
from isf.repair import clearance
from isf.collision.checker import Plane
from isf.warming import warm_up
from isf.planning._evaluation import SampleJudge
from isf.fitting.engine import score_fit
from isf.result import FitStatus


def settings(parser, texts: list[str], cls: type = isf.RepairConfig,
             option: str = "--setting") -> dict:
    """``{"default": cls(), NAME: cls(...), ...}`` from ``NAME:KEY=VALUE,...`` (``cls``:
    ``isf.RepairConfig`` or ``isf.FitConfig``)."""
    out = {"default": cls()}
    for text in texts:
        name, _, fields = text.partition(":")
        if not name or not fields or name in out:
            parser.error(f"{option} {text!r} must look like NAME:KEY=VALUE,... with a new NAME")
        out[name] = _common.parse_config(parser, fields, f"{option} {name}", cls)
    return out


def opposed_normals(repairer: clearance.ClearanceRepair) -> list[float]:
    """Record, on this repairer, the first step's most opposed pair of row normals within one
    element (a dot product; 1.0 when no element has two rows) of every repair: appended to the
    returned list, one value per repair (NaN for a repair that takes no step). The recording
    costs every setting the same small overhead in the CPU times."""
    record, last = [], {}
    violations, active_rows = repairer._violations, repairer._active_rows

    def remember(T, R, p):
        last["rows"] = rows = violations(T, R, p)
        return rows

    def first_step(violation, element):
        chosen = active_rows(violation, element)
        if last.pop("first", False):
            rows, lowest = last["rows"], 1.0
            for e in np.unique(rows.element[chosen]):
                normals = rows.normal[chosen[rows.element[chosen] == e]]
                if len(normals) > 1:
                    lowest = min(lowest, float((normals @ normals.T).min()))
            record.append(lowest)
        return chosen

    repair = repairer.repair

    def marked(T, q, **kwargs):
        last["first"] = True
        before = len(record)
        out = repair(T, q, **kwargs)
        if len(record) == before:  # no step taken
            record.append(np.nan)
        last.pop("first", None)
        return out

    repairer._violations, repairer._active_rows, repairer.repair = remember, first_step, marked
    return record


def corpus_report(path: str, configs: dict[str, isf.RepairConfig], quick: bool):
    """The tables of the ``corpus`` command."""
    warm_up()
    passes, opposition, totals = [], [], {name: [0, 0, 0.0, 0] for name in configs}
    for label, gripper, obj, cases in stored_configurations(path):
        cases = cases[:8] if quick else cases
        checker = SampleJudge(gripper, obj, isf.FitConfig(), repair=False).checker
        outcome = {}
        for name, config in configs.items():
            repairer = clearance.ClearanceRepair(gripper, obj, config)
            repairer.repair(*cases[0][:2], **cases[0][2])  # caches warm
            record = opposed_normals(repairer)
            start = time.process_time()
            outs = [repairer.repair(T, q, **kwargs) for T, q, kwargs, _ in cases]
            cpu = time.process_time() - start
            passed = np.array([checker.check(o.T_object_gripper, o.q).collision_free for o in outs])
            distance = np.array([score_fit(gripper, obj, o.T_object_gripper, o.q, isf.FitConfig(),
                                           FitStatus.CONVERGED, (), 0.0).mean_distance
                                 for o in outs])
            outcome[name] = (passed, cpu, sum(o.iterations for o in outs), distance,
                             np.array(record[-len(cases):]))
        every = np.logical_and.reduce([o[0] for o in outcome.values()])
        base = outcome["default"][0]
        for name, (passed, cpu, steps, distance, _) in outcome.items():
            totals[name][0] += int(passed.sum())
            totals[name][1] += len(passed)
            totals[name][2] += cpu
            totals[name][3] += steps
            changes = f"-{(base & ~passed).sum()} +{(~base & passed).sum()}"
            passes.append([label, name, len(cases), f"{passed.sum()} ({changes})", f"{cpu:.2f}",
                           steps, _common.fmt(1e3 * distance[every].mean()) if every.any() else "-"])
        for name, (passed, _, _, _, record) in outcome.items():
            if name == "default":
                continue
            default_record = outcome["default"][4]
            for b in (True, False):
                for s in (True, False):
                    group = (base == b) & (passed == s)
                    if group.any():
                        opposition.append([
                            label, name, f"{'pass' if b else 'fail'} / {'pass' if s else 'fail'}",
                            int(group.sum()), f"{np.nanmedian(record[group]):+.2f}",
                            f"{np.nanmedian(default_record[group]):+.2f}"])
    total_rows = [[name, f"{v[0]} of {v[1]}", f"{v[2]:.2f}", v[3]] for name, v in totals.items()]
    return [
        "#### Repairs that pass the planner's re-check (-lost +gained against the default)",
        _common.markdown_table(["configuration", "setting", "repairs", "passing", "CPU s",
                                "steps", "mean distance (mm), repairs passing with every setting"],
                               passes),
        _common.markdown_table(["setting", "passing", "CPU s", "steps"], total_rows),
        "#### The most opposed row normals within one element, first step (median dot product)",
        _common.markdown_table(["configuration", "setting", "outcome: default / setting",
                                "repairs", "with the setting", "with the default"], opposition),
    ]


def plan_objects(gripper_name: str, count: int):
    """The gripper and its ``count`` benchmark objects."""
    if gripper_name == "paper":
        return isf.load_gripper("paper-parallel"), [
            _common.scaled_benchmark_object(name, max_points=2000)[0]
            for name in DEFAULT_OBJECTS[:count]]
    objects, _ = bench_hands.load_objects(count)
    if gripper_name == "three":
        return isf.load_gripper("three-finger"), objects
    return bench_hands.tagged_allegro(Path(tempfile.mkdtemp())), objects


def seed_list(parser, text: str) -> list[int]:
    """Seeds from ``A-B`` (inclusive) or ``A,B,...``."""
    try:
        if "-" in text:
            first, last = (int(v) for v in text.split("-"))
            return list(range(first, last + 1))
        return [int(v) for v in text.split(",")]
    except ValueError:
        parser.error(f"--seeds {text!r}: give A-B or A,B,... (integers)")


def plans_report(gripper_name: str, count: int, seeds: list[int],
                 configs: dict[str, tuple[isf.FitConfig, isf.RepairConfig]], on_table: bool = False):
    """The table of the ``plans`` command (``configs``: per setting, its ISF and repair
    parameters); ``on_table``: each object rests on a table (a plane through its lowest point,
    normal +z), which every link must also keep clear of."""
    warm_up()
    gripper, objects = plan_objects(gripper_name, count)
    for fit, repair in configs.values():  # the repairers' caches, once
        isf.plan(gripper, objects[0], samples=3, seed=99, config=fit, repair_collisions=repair)
    runs = {name: [] for name in configs}
    for obj in objects:
        table = [Plane.table(float(obj.points[:, 2].min()))] if on_table else []
        for seed in seeds:
            for name, (fit, repair) in configs.items():
                start = time.process_time()
                result = isf.plan(gripper, obj, samples=60, seed=seed, config=fit,
                                  repair_collisions=repair, obstacles=table)
                cpu = time.process_time() - start
                free = [g for g in result.grasps if g.collision_free]
                touching = [g.fit.mean_distance for g in free if np.isfinite(g.fit.mean_distance)]
                error = np.mean(touching) if touching else np.nan
                iterations = np.mean([g.fit.iterations for g in result.grasps])
                runs[name].append((len(free), sum(g.valid for g in result.grasps), error, cpu,
                                   iterations))
    base = np.array(runs["default"])
    rows = []
    for name, values in runs.items():
        a = np.array(values)
        d, d_valid, d_error = a[:, 0] - base[:, 0], a[:, 1] - base[:, 1], 1e3 * (a[:, 2] - base[:, 2])
        rows.append([name, len(a), _common.fmt(a[:, 0].mean()), _common.mean_and_error(d),
                     f"{(d > 0).sum()} / {(d < 0).sum()}",
                     _common.fmt(a[:, 1].mean()), _common.mean_and_error(d_valid),
                     _common.fmt(1e3 * np.nanmean(a[:, 2])),
                     _common.mean_and_error(d_error[np.isfinite(d_error)]),
                     _common.fmt(a[:, 4].mean()),
                     _common.fmt(np.median(a[:, 3])), _common.fmt(np.median(a[:, 3] / base[:, 3]))])
    return [(f"#### {gripper_name}: {count} objects x seeds {seeds[0]}..{seeds[-1]}, "
             f"60 samples, one thread{', on a table' if on_table else ''}"),
            _common.markdown_table(["setting", "plans", "collision-free per plan",
                                    "difference to default (mean +- s.e.)", "pairs higher / lower",
                                    "valid per plan", "valid: difference to default",
                                    "mean fit error of collision-free (mm)",
                                    "fit error: difference to default (mm; plans with one)",
                                    "ISF iterations per sample",
                                    "CPU s per plan (median)",
                                    "CPU time, setting / default (median of pairs)"], rows)]


def main() -> None:
    parser = _common.base_parser(__doc__.splitlines()[0], repeats=1, budget=0.0)
    parser.add_argument("command", choices=("corpus", "plans"))
    parser.add_argument("corpus", nargs="?", help="corpus: the corpus file")
    parser.add_argument("--setting", action="append", default=[],
                        metavar="NAME:KEY=VALUE,...", help="a repair setting (repeatable)")
    parser.add_argument("--fit-setting", action="append", default=[],
                        metavar="NAME:KEY=VALUE,...",
                        help="plans: an ISF setting (isf.FitConfig; repeatable); a NAME also "
                             "given to --setting plans with both")
    parser.add_argument("--gripper", choices=("paper", "three", "allegro"), default="paper",
                        help="plans: the gripper (default paper)")
    parser.add_argument("--objects", type=int, default=2, help="plans: objects (default 2)")
    parser.add_argument("--seeds", default="0-3", help="plans: seeds, A-B or A,B,... (default 0-3)")
    parser.add_argument("--on-table", action="store_true",
                        help="plans: each object rests on a table the gripper must keep clear of")
    args = parser.parse_args()
    repairs = settings(parser, args.setting)
    fits = settings(parser, args.fit_setting, isf.FitConfig, "--fit-setting")
    configs = {name: (fits.get(name, isf.FitConfig()), repairs.get(name, isf.RepairConfig()))
               for name in dict.fromkeys([*repairs, *fits])}
    started, header = time.perf_counter(), _common.machine_description()
    if args.command == "corpus":
        if args.corpus is None:
            parser.error("corpus: give the corpus file (bench/bench_repair.py --collect FILE)")
        if args.fit_setting:
            parser.error("--fit-setting applies to plans: the corpus holds fits made already")
        sections = corpus_report(args.corpus, repairs, args.quick)
    else:
        seeds = seed_list(parser, args.seeds)
        sections = plans_report(args.gripper, 1 if args.quick else args.objects,
                                seeds[:1] if args.quick else seeds, configs, args.on_table)
    _common.finish("repair_settings: collision-repair and ISF settings compared", [
        "Settings (fields that differ from `FitConfig()` and `RepairConfig()`): " + "; ".join(
            f"`{name}`: {', '.join(filter(None, map(_common.changed_fields, pair))) or 'the default'}"
            for name, pair in configs.items()),
        *sections], started, header, args.out)


if __name__ == "__main__":
    main()
