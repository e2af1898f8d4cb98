"""The ``learned`` sampler against the ``regret`` sampler on objects the models never saw.

For each gripper (``paper-parallel``, ``flat-parallel``, ``three-finger`` and the Franka hand
tagged by ``isf tag``, :func:`isf_sampler_learned.bundled.tagged_franka_hand`), each test
object and each seed, both samplers plan 60 samples (``isf.plan`` defaults otherwise) with the
bundled model of ``isf-sampler-learned``. ``regret`` is the bandit the learned sampler
builds on, without its starts at the centre of mass (``RegretSampler(com_share=0)``): those
aim at grasps that hold, not at valid ones sooner, and would weaken the baseline here. The
script refuses a test object that a model was trained on (the model file lists its objects).

Reported per gripper, object and sampler (medians over the seeds): valid grasps among the first
10 samples, samples to the first valid grasp (61 when none), valid grasps of 60, mean fitting
error of the valid grasps (``FitResult.mean_distance``, finite ones), and the sampler's own
time (``reset``, ``propose``, ``observe``) as a share of the plan's ``total_time``, after a
warm-up plan per sampler and gripper (imports and kernels load once per process). The
summary per gripper gives the targets of the learned sampler: median over objects of the
ratios learned / regret, and the worst object; a second summary covers only the objects where
regret finds at most 6 valid grasps among its first 10, the only ones where a 1.5x ratio of
valid@10 is possible; a last table sums each sampler's medians over the objects (or scenes).

Needs the YCB meshes (``../shared/data/ycb`` or ``$ISF_YCB_DIR``) and the plugin installed
(``pip install -e plugins/isf-sampler-learned``).

``--scenes N`` plans simulated depth images of cluttered tables instead (the scenes of
``bench/bench_scenes.py``: ``bench/scene_sim.py`` renders them, ``isf.load_scene`` reads the
depth images, docs/benchmark-scenes.md), built only of the YCB objects no shipped model saw
(:data:`SCENE_OBJECTS`): scene k has seed k, 3 + (k mod 3) objects and one camera for even k,
two for odd k; ``flat-parallel`` and the Franka hand, the grippers the scene judge is set up
for. Besides the figures above it reports how many of each plan's top 5 valid grasps pass
the ground-truth judge of ``bench/scene_judge.py`` (no penetration beyond 2 mm, every
contact surface touching one and the same object).

``--tuning`` plans the objects the sampler's parameters were chosen on instead
(:data:`TUNING_OBJECTS`, neither training nor test objects; with ``--scenes``, scenes built of
them with seeds from :data:`TUNING_SCENE_SEED` on), and ``--param KEY=VALUE`` gives
the learned sampler a parameter (a JSON value), so that a choice of parameters can be
compared there without touching the test objects.

Run from the repository root:
    python bench/bench_learned.py [--quick] [--seeds 3] [--gripper NAME] [--objects N] [--out FILE]
        [--tuning] [--scenes N] [--param KEY=VALUE ...]
"""

from __future__ import annotations

import _common

import argparse
import json
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

import isf
from isf.samplers.regret import RegretSampler
from isf_sampler_learned import LearnedSampler, gripper_sha256
from isf_sampler_learned.bundled import bundled_model, tagged_franka_hand

GRIPPERS = ("paper-parallel", "flat-parallel", "three-finger", "franka-hand")
TEST_OBJECTS = ("asset:ycb:FoamBrick", "asset:ycb:GelatinBox", "asset:ycb:PottedMeatCan",
                "asset:ycb:Scissors", "asset:ycb:TomatoSoupCan", "asset:dragon",
                "asset:random-400", "asset:random-401")
TUNING_OBJECTS = tuple(f"asset:random-{k}" for k in range(410, 416))
#: the objects of ``--scenes`` (bench/scene_sim.py names): the test objects of the YCB set
SCENE_OBJECTS = tuple(spec.removeprefix("asset:") for spec in TEST_OBJECTS
                      if spec.startswith("asset:ycb:"))
#: the objects of ``--tuning --scenes``
TUNING_SCENE_OBJECTS = tuple(spec.removeprefix("asset:") for spec in TUNING_OBJECTS)
#: the first scene seed of ``--tuning --scenes`` (the test scenes use seeds 0 .. N-1)
TUNING_SCENE_SEED = 1000
SCENE_GRIPPERS = ("flat-parallel", "franka-hand")
SCENE_TOP = 5
QUICK_OBJECTS = 3
SAMPLES = 60
FIRST = 10
TARGET_RATIO = 1.5
HARD = int(FIRST / TARGET_RATIO) + 1
"""Objects where regret's median valid@10 is below this (<= 6 of 10) leave room for a
1.5x ratio; the report summarises them apart."""
TARGETS = "valid@10 >= 1.5x regret; first valid <= 0.5x regret; valid@60 >= regret; " \
          "error <= regret; sampler time <= 10 % of the plan"


def timed(cls: type) -> type:
    """A subclass of sampler class ``cls`` that adds its time in reset, propose and observe to
    ``self.seconds``."""

    class Timed(cls):
        seconds = 0.0

        def _clock(self, method, *args):
            start = time.perf_counter()
            try:
                return method(*args)
            finally:
                self.seconds += time.perf_counter() - start

        def reset(self, obj, gripper, rng):
            self.seconds = 0.0
            return self._clock(super().reset, obj, gripper, rng)

        def propose(self, n, rng):
            return self._clock(super().propose, n, rng)

        def observe(self, outcomes):
            return self._clock(super().observe, outcomes)

    Timed.__name__ = f"Timed{cls.__name__}"
    return Timed


@dataclass(frozen=True)
class Run:
    """One plan's figures."""

    valid_first: int
    first_valid: int
    valid: int
    error_mm: float
    sampler_share: float
    judged: float = float("nan")  # of the top SCENE_TOP valid grasps, those the judge passes


def run_once(gripper: isf.Gripper, obj, sampler_cls: type, seed: int, params: dict,
             judge=None) -> Run:
    """One plan of ``obj`` (an object surface or an ``isf.Scene``); ``judge`` (a
    ``scene_judge.Judge``) judges its top valid grasps."""
    sampler = timed(sampler_cls)(**params)
    result = isf.plan(gripper, obj, samples=SAMPLES, sampler=sampler, seed=seed)
    ordered = sorted(result.grasps, key=lambda g: g.sample_index)
    valid = [g.valid for g in ordered]
    errors = [g.fit.mean_distance for g in ordered if g.valid and np.isfinite(g.fit.mean_distance)]
    top = [g for g in result.grasps if g.valid][:SCENE_TOP]
    return Run(valid_first=sum(valid[:FIRST]),
               first_valid=valid.index(True) + 1 if any(valid) else SAMPLES + 1,
               valid=sum(valid), error_mm=1e3 * float(np.mean(errors)) if errors else float("nan"),
               sampler_share=sampler.seconds / result.stats.total_time,
               judged=float("nan") if judge is None else
               float(sum(judge(g.T_object_gripper, g.q).passed for g in top)))


def median_run(runs: list[Run]) -> Run:
    def med(key):
        values = [getattr(r, key) for r in runs if np.isfinite(getattr(r, key))]
        return statistics.median(values) if values else float("nan")

    return Run(*(med(key) for key in Run.__dataclass_fields__))


def load(name: str, folder: Path) -> isf.Gripper:
    gripper = tagged_franka_hand(folder) if name == "franka-hand" else isf.load_gripper(name)
    model = bundled_model(gripper_sha256(gripper))
    if model is None:
        raise SystemExit(f"no bundled model for {name}: run "
                         "plugins/isf-sampler-learned/scripts/train_bundled.py")
    seen = set(TEST_OBJECTS + TUNING_OBJECTS) & set(model.info.get("objects", ()))
    if seen:
        raise SystemExit(f"the {name} model was trained on test objects {sorted(seen)}")
    return gripper


class Comparison(NamedTuple):
    """``learned`` against ``regret`` on one object (medians over the seeds)."""

    object: str
    regret_first: float
    valid_first_ratio: float
    first_valid_ratio: float
    valid_difference: float
    error_ratio: float
    sampler_share: float


SUMMARY_HEADER = ["gripper", "objects", "valid@10 ratio", "first-valid ratio",
                  "valid@60 difference", "error ratio", "sampler time (max)"]


def summarise(gripper: str, objects: str, rows: list[Comparison]) -> list[str]:
    """A summary row: median over ``rows`` with the worst object in brackets."""
    def cell(values, worst):
        return f"{_common.fmt(statistics.median(values))} (worst {_common.fmt(worst(values))})"

    return [gripper, objects,
            cell([r.valid_first_ratio for r in rows], min),
            cell([r.first_valid_ratio for r in rows], max),
            cell([r.valid_difference for r in rows], min),
            cell([r.error_ratio for r in rows], max),
            f"{100 * max(r.sampler_share for r in rows):.1f} %"]


def warm_up(gripper: isf.Gripper) -> None:
    """A short plan per sampler, so that one-off costs (imports, kernels, the bundled model)
    do not count in the first measured plan."""
    obj = isf.open_object("shape:box")
    for cls in (RegretSampler, LearnedSampler):
        isf.plan(gripper, obj, samples=2, sampler=cls(), seed=0)


class Case(NamedTuple):
    """What one row plans: an object, or a scene with its ground truth."""

    name: str
    obj: object  # isf.ObjectSurface or isf.Scene
    truth: object = None  # scene_sim.Scene of a scene

    def judge(self, gripper: isf.Gripper):
        import scene_judge

        return scene_judge.Judge(gripper, self.truth)


def scene_cases(count: int, objects: tuple[str, ...], first_seed: int = 0) -> list[Case]:
    """``count`` scenes of ``objects`` (bench/scene_sim.py names), seeds ``first_seed`` on,
    rendered and read by ``isf.load_scene``; scene k has 3 + (k mod 3) objects and 1 + (k mod 2)
    cameras."""
    import bench_scenes
    import scene_sim

    catalogue = scene_sim.catalogue(list(objects))
    cases = []
    for k in range(count):
        seed = first_seed + k
        truth = scene_sim.random_scene(catalogue, 3 + k % 3, seed)
        cameras = scene_sim.random_cameras(np.random.default_rng(seed), 1 + k % 2)
        rendered = bench_scenes.render(truth, cameras, seed, "auto")
        if rendered.scene is None:
            raise SystemExit(f"isf.load_scene refused scene {seed}: {rendered.error}")
        cases.append(Case(f"scene {seed} ({len(truth.objects)} objects, {len(cameras)} "
                          f"camera{'s' if len(cameras) > 1 else ''})", rendered.scene, truth))
    return cases


def ratio(a: float, b: float) -> float:
    return a / b if b else (float("inf") if a else 1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 (default 3)")
    parser.add_argument("--gripper", action="append", choices=GRIPPERS)
    parser.add_argument("--quick", action="store_true",
                        help=f"one seed, the first {QUICK_OBJECTS} objects")
    parser.add_argument("--objects", type=int, help="the first N test objects only")
    parser.add_argument("--out", help="also write the markdown report to this file")
    parser.add_argument("--tuning", action="store_true",
                        help="plan the tuning objects random-410 .. random-415 instead")
    parser.add_argument("--scenes", type=int, default=0, metavar="N",
                        help="plan N simulated cluttered scenes of unseen objects instead")
    parser.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                        help="a parameter of the learned sampler, VALUE in JSON (repeatable)")
    args = parser.parse_args()
    seeds = range(1 if args.quick else args.seeds)
    pool = TUNING_OBJECTS if args.tuning else TEST_OBJECTS
    objects = pool[:QUICK_OBJECTS if args.quick else args.objects]
    grippers = args.gripper or (SCENE_GRIPPERS if args.scenes else GRIPPERS)
    if args.scenes and set(grippers) - set(SCENE_GRIPPERS):
        raise SystemExit(f"--scenes runs the grippers of the scene judge, {SCENE_GRIPPERS}: "
                         "leave out --gripper or name one of them")
    try:
        params = {key: json.loads(value) for key, _, value in
                  (item.partition("=") for item in args.param)}
    except json.JSONDecodeError as err:
        raise SystemExit(f"--param needs KEY=VALUE with a JSON value: {err}") from None

    warnings.simplefilter("ignore")  # objects larger than a jaw's opening are expected
    started = time.perf_counter()
    header = ["gripper", "object", "sampler", "valid@10", "first valid", "valid@60",
              "error (mm)", "sampler time"]
    header += [f"top {SCENE_TOP} passing the judge"] if args.scenes else []
    if args.scenes:
        cases = scene_cases(args.scenes, TUNING_SCENE_OBJECTS, TUNING_SCENE_SEED) \
            if args.tuning else scene_cases(args.scenes, SCENE_OBJECTS)
    else:
        cases = [Case(spec.removeprefix("asset:"), isf.open_object(spec)) for spec in objects]
    rows, summary, hard_summary, totals = [], [], [], []
    with tempfile.TemporaryDirectory() as folder:
        for name in grippers:
            gripper = load(name, Path(folder))
            warm_up(gripper)
            ratios, summed = [], {}
            for case in cases:
                judge = None if case.truth is None else case.judge(gripper)
                medians = {}
                for label, cls, kwargs in (("regret", RegretSampler, {"com_share": 0}),
                                           ("learned", LearnedSampler, params)):
                    medians[label] = m = median_run([run_once(gripper, case.obj, cls, s, kwargs,
                                                              judge) for s in seeds])
                    summed[label] = [a + b for a, b in zip(summed.get(label, [0.0] * 3),
                                                           (m.valid_first, m.valid, m.judged))]
                    rows.append([name, case.name, label, _common.fmt(m.valid_first),
                                 _common.fmt(m.first_valid), _common.fmt(m.valid),
                                 _common.fmt(m.error_mm), f"{100 * m.sampler_share:.1f} %"])
                    rows[-1] += [_common.fmt(m.judged)] if args.scenes else []
                    print(" | ".join(rows[-1]), flush=True)
                r, l = medians["regret"], medians["learned"]
                ratios.append(Comparison(case.name, r.valid_first,
                                         ratio(l.valid_first, r.valid_first),
                                         ratio(l.first_valid, r.first_valid), l.valid - r.valid,
                                         ratio(l.error_mm, r.error_mm), l.sampler_share))
            summary.append(summarise(name, "all scenes" if args.scenes else "all", ratios))
            totals += [[name, label, *(_common.fmt(v) for v in values[:3 if args.scenes else 2])]
                       for label, values in summed.items()]
            hard = [row for row in ratios if row.regret_first < HARD]
            if hard:
                hard_summary.append(summarise(name, ", ".join(row.object for row in hard), hard))
    report = "\n\n".join([
        f"Command: `{' '.join(['python', *sys.argv])}`; seeds {list(seeds)}; "
        f"{time.perf_counter() - started:.0f} s.",
        _common.machine_description(),
        f"Per gripper, {'scene' if args.scenes else 'object'} and sampler (medians over the "
        "seeds):",
        _common.markdown_table(header, rows),
        f"Targets of `learned` against `regret` ({TARGETS}); median over objects (worst object):",
        _common.markdown_table(SUMMARY_HEADER, summary),
        f"The same on the objects where `regret` finds fewer than {HARD} valid grasps among its "
        f"first {FIRST} samples (where a {TARGET_RATIO}x ratio can exist):",
        _common.markdown_table(SUMMARY_HEADER, hard_summary),
        f"Summed over the {'scenes' if args.scenes else 'objects'} (medians over the seeds):",
        _common.markdown_table(["gripper", "sampler", "valid@10", "valid@60",
                                *([f"top {SCENE_TOP} passing the judge"] if args.scenes else [])],
                               totals),
    ])
    print(report)
    if args.out:
        Path(args.out).write_text(report + "\n")


if __name__ == "__main__":
    main()
