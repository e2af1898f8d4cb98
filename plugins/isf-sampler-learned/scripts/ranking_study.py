"""Compare model classes by how well they rank the starts of objects they did not see.

Reads the examples that ``train_bundled.py --cache DIR`` keeps, splits each gripper's
training objects into ``--folds`` groups (object ``k`` in group ``k % folds``), fits on the
others and scores each group, then reports the within-object figures
(:func:`isf_sampler_learned.training.object_ranking`): mean per-object AUC and the valid share
of each object's top 10 % starts. Model classes: the plugin's additive hinge logistic
regression at two L2 penalties, and gradient-boosted trees (LightGBM, when installed).

``--learning-curve`` instead fits the shipped model class (l2 1) on a random third, two thirds
and all of each fold's training objects (three draws of the fractions, seed 0) and reports the
mean per-object AUC of each: whether more objects of the same kind would rank better.

Run from the repository root:
    python plugins/isf-sampler-learned/scripts/ranking_study.py --cache DIR [--folds 4]
        [--learning-curve]
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


def gripper_of(path: Path) -> str:
    """The gripper of a ``train_bundled.py --cache`` file
    (``NAME-N-objects-seedS-samplesM.npz``)."""
    return path.name.split("-objects")[0].rsplit("-", 1)[0]


FRACTIONS = (1 / 3, 2 / 3, 1.0)
DRAWS = 3


def cross_validated(examples: Examples, folds: int, fit_predict) -> np.ndarray:
    """Each example's score from a model fitted on the other folds' objects (object ``k`` in
    fold ``k % folds``), shape (M,)."""
    score = np.zeros(len(examples.valid))
    for fold in range(folds):
        test = examples.group % folds == fold
        score[test] = fit_predict(examples.subset(~test), examples.subset(test))
    return score


def learning_curve(examples: Examples, folds: int, rng: np.random.Generator) -> list[float]:
    """Mean per-object AUC with :data:`FRACTIONS` of each fold's training objects (the mean
    over :data:`DRAWS` random draws of them; one for all)."""
    fit = hinge(1.0)
    aucs = []
    for fraction in FRACTIONS:
        draws = []
        for _ in range(1 if fraction == 1.0 else DRAWS):
            def fit_fraction(train: Examples, test: Examples, fraction=fraction) -> np.ndarray:
                objects = np.unique(train.group)
                keep = rng.choice(objects, size=max(2, round(fraction * len(objects))),
                                  replace=False)
                return fit(train.subset(np.isin(train.group, keep)), test)
            score = cross_validated(examples, folds, fit_fraction)
            draws.append(object_ranking(score, examples.valid, examples.group).auc)
        aucs.append(float(np.mean(draws)))
    return aucs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, required=True,
                        help="the folder train_bundled.py --cache filled")
    parser.add_argument("--folds", type=int, default=4)
    parser.add_argument("--learning-curve", action="store_true",
                        help="per-object AUC with a third, two thirds and all training objects")
    args = parser.parse_args()
    if args.learning_curve:
        rng = np.random.default_rng(0)
        print("| gripper | examples | " + " | ".join(
            f"per-object AUC, {fraction:.0%} of the objects" for fraction in FRACTIONS)
            + " |\n|---|---|" + "---|" * len(FRACTIONS))
        for path in sorted(args.cache.glob("*.npz")):
            examples = Examples.load(path)
            aucs = learning_curve(examples, args.folds, rng)
            print(f"| {gripper_of(path)} | {len(examples.valid)} | "
                  + " | ".join(f"{auc:.3f}" for auc in aucs) + " |", flush=True)
        return
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
            score = cross_validated(examples, args.folds, fit_predict)
            ranking = object_ranking(score, examples.valid, examples.group)
            print(f"| {gripper_of(path)} | {label} | "
                  f"{ranking.auc:.3f} | {ranking.top_decile_valid:.3f} | "
                  f"{ranking.valid_rate:.3f} |", flush=True)


if __name__ == "__main__":
    main()
