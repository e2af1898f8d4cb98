"""Compare model classes by how well they rank the starts of objects they did not see.

Reads the examples that ``train_bundled.py --cache DIR`` keeps, splits each gripper's
training objects into ``--folds`` groups (object ``k`` in group ``k % folds``), fits on the
others and scores each group, then reports the within-object figures
(:func:`isf_sampler_learned.training.object_ranking`): mean per-object AUC and the valid share
of each object's top 10 % starts. Model classes: the plugin's additive hinge logistic
regression at two L2 penalties, and gradient-boosted trees (LightGBM, when installed).

Run from the repository root:
    python plugins/isf-sampler-learned/scripts/ranking_study.py --cache DIR [--folds 4]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from isf_sampler_learned.model import fit_model
from isf_sampler_learned.training import Examples, object_ranking


def hinge(l2: float):
    def fit_predict(train: Examples, test: Examples) -> np.ndarray:
        model = fit_model(train.features, train.valid, train.error, gripper_sha256="study",
                          gripper_name="study", l2=l2)
        return model.p_valid(test.features)
    return fit_predict


def boosted_trees(train: Examples, test: Examples) -> np.ndarray:
    import lightgbm

    params = dict(objective="binary", learning_rate=0.03, num_leaves=7, min_data_in_leaf=80,
                  feature_fraction=0.8, bagging_fraction=0.8, bagging_freq=1, lambda_l2=1.0,
                  num_threads=1, seed=0, deterministic=True, force_col_wise=True, verbose=-1)
    booster = lightgbm.train(params, lightgbm.Dataset(train.features, train.valid.astype(float)),
                             num_boost_round=400)
    return booster.predict(test.features)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, required=True,
                        help="the folder train_bundled.py --cache filled")
    parser.add_argument("--folds", type=int, default=4)
    args = parser.parse_args()
    methods = {"hinge logistic, l2 1": hinge(1.0), "hinge logistic, l2 10": hinge(10.0)}
    try:
        import lightgbm  # noqa: F401
        methods["LightGBM, 400 trees of 7 leaves"] = boosted_trees
    except ImportError:
        print("LightGBM is not installed: boosted trees left out")
    print("| gripper | model | per-object AUC | valid among each object's top 10 % | "
          "valid (all) |\n|---|---|---|---|---|")
    for path in sorted(args.cache.glob("*.npz")):
        examples = Examples.load(path)
        for label, fit_predict in methods.items():
            score = np.zeros(len(examples.valid))
            for fold in range(args.folds):
                test = examples.group % args.folds == fold
                score[test] = fit_predict(examples.subset(~test), examples.subset(test))
            ranking = object_ranking(score, examples.valid, examples.group)
            name = path.name.split('-objects')[0].rsplit('-', 1)[0]
            print(f"| {name} | {label} | "
                  f"{ranking.auc:.3f} | {ranking.top_decile_valid:.3f} | "
                  f"{ranking.valid_rate:.3f} |", flush=True)


if __name__ == "__main__":
    main()
