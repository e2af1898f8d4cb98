"""How well does each feature of a start, alone, rank the starts of one object by validity?

For a gripper and a set of objects, plans each object with the ``uniform`` and ``regret``
samplers (60 samples each, the plans seeded 0, 1, 2, ... in turn) and keeps every
sample's start and outcome (:func:`isf_sampler_learned.training.plan_starts`). Each start is
described by the plugin's features (:data:`isf_sampler_learned.features.FEATURE_NAMES`) and by
the open gripper's collision state there (isf's collision check at ``q_initial``):

- ``start_penetration``: how deep the gripper sits in the object at the start, metres;
- ``backoff_to_clear``: how far it must back off against its approach axis before it is
  collision-free, in openings (2 when it is not within 2 openings);
- ``clear_share``: the share of 21 poses backed off by 0 to 2 openings that are
  collision-free.

Printed per feature: the mean over the plans of its within-plan AUC for validity (0.5: no
better than chance; a feature that ranks the other way reads below 0.5) and the mean of
``|AUC - 0.5|``, the strength of the ranking in either direction. The sampler ranks the
starts of one object, so these within-object figures are what a feature can give it.

``--scenes N`` studies the starts of the ``regret`` and ``learned`` samplers on simulated
camera scenes of clutter instead: the tuning scenes of ``bench/bench_learned.py --tuning
--scenes N`` (objects no benchmark plans, seeds 1000 on). There the collision state is
checked against everything the plan avoids (the table and the space the cameras did not see,
as well as the surface), and two quantities only a scene has are added:

- ``approach_down``: the cosine between the approach axis and the downward table normal (1: a
  start from straight above);
- ``closing_ends_facing``: whether the surface was seen at both ends of the closing line: of
  the piece's points within the closing tube, those within a tenth of an opening of either
  end, the smaller of the two ends' mean outward normal along the closing axis (1: two
  opposite faces seen, -1 or less: one face or none).

Also printed: the within-plan AUC of the shipped model's ``P(valid)``, and of a model of the
same class fitted on the scenes' own starts (the plugin's features), each scene scored by a
model fitted on the others.

Run from the repository root:
    python plugins/isf-sampler-learned/scripts/feature_study.py [--gripper franka-hand]
        [--objects asset:duck,asset:mug,...] [--scenes N]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

import isf
from isf.collision import CollisionChecker
from isf_sampler_learned.bundled import bundled_model, tagged_franka_hand
from isf_sampler_learned.features import (
    FEATURE_NAMES,
    ObjectDescriptors,
    gripper_axes,
    gripper_sha256,
)
from isf_sampler_learned.model import fit_model
from isf_sampler_learned.training import PlannedStarts, object_ranking, plan_starts

OBJECTS = ("asset:duck", "asset:mug", "asset:bunny", "asset:bread", "asset:random-003",
           "asset:random-005", "asset:ycb:MustardBottle", "asset:ycb:PowerDrill")
"""Training objects of the shipped models (``train_bundled.py``), none of the benchmark's."""
BACKOFF_STEPS = np.linspace(0.0, 2.0, 21)
"""How far the start is backed off against the approach axis, in openings."""
COLLISION_FEATURES = ("start_penetration", "backoff_to_clear", "clear_share")
SCENE_FEATURES = ("approach_down", "closing_ends_facing")
SCENE_SAMPLERS = ("regret", "learned")
END_SHARE = 0.1
"""Points within this many openings of an end of the closing line belong to that end."""
TUBE = 0.25
"""Radius of the closing tube, in openings (as the plugin's features)."""
BENCH = Path(__file__).resolve().parents[3] / "bench"


def collision_features(checker: CollisionChecker, gripper, axes, T: np.ndarray) -> np.ndarray:
    """:data:`COLLISION_FEATURES` of starts ``T`` (M, 4, 4); shape (M, 3)."""
    rows = []
    q = np.repeat(gripper.q_initial[None], len(BACKOFF_STEPS), axis=0)
    for T_start in T:
        approach = T_start[:3, :3] @ axes.approach
        poses = np.repeat(T_start[None], len(BACKOFF_STEPS), axis=0)
        poses[:, :3, 3] -= (BACKOFF_STEPS * axes.opening)[:, None] * approach
        reports = checker.check_many(poses, q)
        clear = np.array([r.collision_free for r in reports])
        first_clear = BACKOFF_STEPS[np.argmax(clear)] if clear.any() else BACKOFF_STEPS[-1]
        rows.append([reports[0].penetration, first_clear, clear.mean()])
    return np.array(rows)


def scene_features(planned: PlannedStarts, axes, up: np.ndarray) -> np.ndarray:
    """:data:`SCENE_FEATURES` of a scene plan's starts, given the table's upward normal ``up``
    (3,); shape (M, 2)."""
    descriptors = ObjectDescriptors.build(planned.surface, axes)
    T = planned.T_object_gripper
    centres = T[:, :3, :3] @ axes.centre + T[:, :3, 3]
    _, nearest = descriptors.tree.query(centres)
    rows = []
    for centre, R, point in zip(centres, T[:, :3, :3], nearest):
        on = np.flatnonzero(descriptors.piece == descriptors.piece[point])
        closing = R @ axes.closing
        offset = descriptors.points[on] - centre
        along = offset @ closing
        inside = np.linalg.norm(offset - along[:, None] * closing, axis=1) < TUBE * axes.opening
        facing = -1.0
        if inside.sum() >= 2:
            along, outward = along[inside], descriptors.normals[on[inside]] @ closing
            band = END_SHARE * axes.opening
            facing = min(outward[along > along.max() - band].mean(),
                         -outward[along < along.min() + band].mean())
        rows.append([-(R @ axes.approach) @ up, facing])
    return np.array(rows)


def within_plan_aucs(scores: np.ndarray, valid: np.ndarray, plans: np.ndarray) -> np.ndarray:
    """Each plan's AUC of ``scores`` (M,) for ``valid`` (M,), plans where both labels occur."""
    aucs = [object_ranking(scores[plans == p], valid[plans == p],
                           np.zeros(int((plans == p).sum()), dtype=int)).auc
            for p in np.unique(plans)]
    return np.array([a for a in aucs if a is not None])


def scene_study(gripper, axes, count: int, samples: int):
    """Plan the first ``count`` tuning scenes with :data:`SCENE_SAMPLERS`; the starts' columns
    (features, collision state, :data:`SCENE_FEATURES`), labels, errors, plan and scene of
    each."""
    sys.path.insert(0, str(BENCH))
    import bench_learned  # the scenes of the learned sampler's benchmark

    cases = bench_learned.scene_cases(count, bench_learned.TUNING_SCENE_OBJECTS,
                                      bench_learned.TUNING_SCENE_SEED)
    columns, valid, error, plans, scenes = [], [], [], [], []
    k = 0
    for s, case in enumerate(cases):
        scene = case.obj
        up = scene.table.normal if scene.table is not None else np.array([0.0, 0.0, 1.0])
        for sampler in SCENE_SAMPLERS:
            planned = plan_starts(gripper, scene, sampler, samples=samples, seed=k)
            k += 1
            checker = CollisionChecker(gripper, planned.surface, obstacles=scene.obstacles,
                                       hidden=scene.unseen)
            T = planned.T_object_gripper
            columns.append(np.hstack([planned.features(axes),
                                      collision_features(checker, gripper, axes, T),
                                      scene_features(planned, axes, up)]))
            valid.append(planned.valid)
            error.append(planned.error)
            plans.append(np.full(len(T), k))
            scenes.append(np.full(len(T), s))
            print(f"# {case.name} {sampler}: {int(planned.valid.sum())}/{len(T)} valid", flush=True)
    return tuple(np.concatenate(a) for a in (columns, valid, error, plans, scenes))


def object_study(gripper, axes, objects: list[str], samples: int):
    """Plan ``objects`` with ``uniform`` and ``regret``; the starts' columns (features and
    collision state), labels and plan of each."""
    columns, valid, plans = [], [], []
    k = 0
    for spec in objects:
        obj = isf.open_object(spec)
        for sampler in ("uniform", "regret"):
            planned = plan_starts(gripper, obj, sampler, samples=samples, seed=k)
            k += 1
            T = planned.T_object_gripper
            checker = CollisionChecker(gripper, planned.surface)
            columns.append(np.hstack([planned.features(axes),
                                      collision_features(checker, gripper, axes, T)]))
            valid.append(planned.valid)
            plans.append(np.full(len(T), k))
            print(f"# {spec} {sampler}: {int(planned.valid.sum())}/{len(T)} valid", flush=True)
    return tuple(np.concatenate(a) for a in (columns, valid, plans))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gripper", default="franka-hand",
                        help="a bundled gripper, or franka-hand (tagged as train_bundled.py tags it)")
    parser.add_argument("--objects", default=",".join(OBJECTS))
    parser.add_argument("--scenes", type=int, default=0, metavar="N",
                        help="study the starts on N tuning scenes of clutter instead")
    parser.add_argument("--samples", type=int, default=60)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # objects far larger than a jaw's opening are expected
    names = [*FEATURE_NAMES, *COLLISION_FEATURES]
    with tempfile.TemporaryDirectory() as folder:
        gripper = (tagged_franka_hand(Path(folder)) if args.gripper == "franka-hand"
                   else isf.load_gripper(args.gripper))
        axes = gripper_axes(gripper)
        if args.scenes:
            names += SCENE_FEATURES
            columns, valid, error, plans, scenes = scene_study(gripper, axes, args.scenes,
                                                               args.samples)
        else:
            columns, valid, plans = object_study(gripper, axes, args.objects.split(","),
                                                 args.samples)
    print("| feature | mean within-plan AUC | mean abs(AUC - 0.5) |\n|---|---|---|")
    for j, name in enumerate(names):
        aucs = within_plan_aucs(columns[:, j], valid, plans)
        print(f"| {name} | {aucs.mean():.3f} | {np.abs(aucs - 0.5).mean():.3f} |")
    if not args.scenes:
        return
    features = columns[:, :len(FEATURE_NAMES)]
    digest = gripper_sha256(gripper)
    shipped = bundled_model(digest)
    refitted = np.zeros(len(valid))
    for s in np.unique(scenes):
        train = scenes != s
        model = fit_model(features[train], valid[train], error[train], gripper_sha256=digest,
                          gripper_name=gripper.name)
        refitted[~train] = model.p_valid(features[~train])
    for label, score in (("shipped model, P(valid)", shipped.p_valid(features)),
                         ("model fitted on the other scenes, P(valid)", refitted)):
        aucs = within_plan_aucs(score, valid, plans)
        print(f"| {label} | {aucs.mean():.3f} | {np.abs(aucs - 0.5).mean():.3f} |")
    print(f"# {int(valid.sum())} of {len(valid)} starts valid over {len(np.unique(plans))} plans")


if __name__ == "__main__":
    main()
