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

Run from the repository root:
    python plugins/isf-sampler-learned/scripts/feature_study.py [--gripper franka-hand]
        [--objects asset:duck,asset:mug,...]
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np

import isf
from isf.collision import CollisionChecker
from isf_sampler_learned.bundled import tagged_franka_hand
from isf_sampler_learned.features import FEATURE_NAMES, gripper_axes
from isf_sampler_learned.training import object_ranking, plan_starts

OBJECTS = ("asset:duck", "asset:mug", "asset:bunny", "asset:bread", "asset:random-003",
           "asset:random-005", "asset:ycb:MustardBottle", "asset:ycb:PowerDrill")
"""Training objects of the shipped models (``train_bundled.py``), none of the benchmark's."""
BACKOFF_STEPS = np.linspace(0.0, 2.0, 21)
"""How far the start is backed off against the approach axis, in openings."""
COLLISION_FEATURES = ("start_penetration", "backoff_to_clear", "clear_share")


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gripper", default="franka-hand",
                        help="a bundled gripper, or franka-hand (tagged as train_bundled.py tags it)")
    parser.add_argument("--objects", default=",".join(OBJECTS))
    parser.add_argument("--samples", type=int, default=60)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # objects far larger than a jaw's opening are expected
    names = (*FEATURE_NAMES, *COLLISION_FEATURES)
    scores, valid, plans = [], [], []
    with tempfile.TemporaryDirectory() as folder:
        gripper = (tagged_franka_hand(Path(folder)) if args.gripper == "franka-hand"
                   else isf.load_gripper(args.gripper))
        axes = gripper_axes(gripper)
        k = 0
        for spec in args.objects.split(","):
            obj = isf.open_object(spec)
            for sampler in ("uniform", "regret"):
                planned = plan_starts(gripper, obj, sampler, samples=args.samples, seed=k)
                k += 1
                T = planned.T_object_gripper
                features = planned.features(axes)
                checker = CollisionChecker(gripper, planned.surface)
                scores.append(np.hstack([features, collision_features(checker, gripper, axes, T)]))
                valid.append(planned.valid)
                plans.append(np.full(len(T), k))
                print(f"# {spec} {sampler}: {int(planned.valid.sum())}/{len(T)} valid", flush=True)
    scores, valid, plans = np.concatenate(scores), np.concatenate(valid), np.concatenate(plans)
    print("| feature | mean within-plan AUC | mean abs(AUC - 0.5) |\n|---|---|---|")
    for j, name in enumerate(names):
        aucs = [object_ranking(scores[plans == p, j], valid[plans == p],
                               np.zeros(int((plans == p).sum()), dtype=int)).auc
                for p in np.unique(plans)]
        aucs = np.array([a for a in aucs if a is not None])
        print(f"| {name} | {aucs.mean():.3f} | {np.abs(aucs - 0.5).mean():.3f} |")


if __name__ == "__main__":
    main()
