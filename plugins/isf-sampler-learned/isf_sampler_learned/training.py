"""Training data from isf's own plans, and the model fitted to it.

Every sample of a plan is an example: its start (the proposal's pose), described by
:func:`~isf_sampler_learned.features.candidate_features` on the surface the plan matched
against, and its outcome: ``valid`` (:attr:`isf.Grasp.valid`: collision-free and every
contact surface touching) and the fitting error (:attr:`isf.FitResult.mean_distance`,
metres). The plans run the existing samplers (``uniform`` and ``regret`` by default, with
:data:`SAMPLER_PARAMS`), seeded ``seed + k`` for the k-th plan, so the examples, and the model,
are the same for a seed.

Held-out figures are measured on whole objects the model did not see: every
``holdout``-th object (in the order given) is left out of a first fit and scored by it; the
model written is then fitted on all objects. Since the sampler ranks the starts of one object,
the figures that matter are within each object (its AUC, the valid share of its top 10 %), not
the accuracy at a threshold of 0.5.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from isf.object.surface import ObjectSurface
from isf.samplers import Outcome, Proposal, Sampler, get_sampler

from .features import (
    FEATURE_NAMES,
    FEATURE_VERSION,
    GripperAxes,
    ObjectDescriptors,
    candidate_features,
    gripper_axes,
    gripper_sha256,
)
from .model import L2, LearnedModel, fit_model

__all__ = ["SAMPLER_PARAMS", "Examples", "HeldOut", "ObjectRanking", "PlannedStarts",
           "collect_examples", "held_out_accuracy", "object_ranking", "plan_starts", "train"]

logger = logging.getLogger(__name__)


#: Parameters of the named samplers whose starts become examples. The regret sampler runs
#: as the learned sampler's own bandit does, every start on a cluster centre on the surface:
#: its default starts half of a plan at the object's centre of mass, which the learned
#: sampler never proposes.
SAMPLER_PARAMS: dict[str, dict] = {"regret": {"com_share": 0.0}}


@dataclass(frozen=True)
class Examples:
    """Labelled starts.

    Attributes:
        features: shape (M, F), see :data:`~isf_sampler_learned.features.FEATURE_NAMES`.
        valid: shape (M,), bool.
        error: fitting error, metres, shape (M,).
        group: index of the object each example came from, shape (M,).
    """

    features: np.ndarray
    valid: np.ndarray
    error: np.ndarray
    group: np.ndarray

    def subset(self, keep: np.ndarray) -> Examples:
        """The examples selected by the boolean mask ``keep``."""
        return Examples(self.features[keep], self.valid[keep], self.error[keep],
                        self.group[keep])

    def save(self, path: str | os.PathLike) -> Path:
        """Write the examples to ``path`` (``.npz``, plain arrays) to refit without replanning."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as stream:
            np.savez(stream, feature_names=np.array(FEATURE_NAMES), features=self.features,
                     valid=self.valid, error=self.error, group=self.group)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> Examples:
        """Read examples written by :meth:`save` (no pickle).

        Raises:
            ValueError: the file holds features of another definition.
        """
        with np.load(path, allow_pickle=False) as data:
            if tuple(data["feature_names"].tolist()) != FEATURE_NAMES:
                raise ValueError(f"{path} holds other features than {FEATURE_VERSION}")
            return cls(data["features"], data["valid"], data["error"], data["group"])


@dataclass(eq=False, kw_only=True)
class _RecordingSampler(Sampler):
    """Runs ``inner`` and keeps every proposal it made, numbered in ``record["start"]``."""

    name = "recording"
    description = "another sampler, its proposals kept"

    inner: Sampler
    starts: list[Proposal] = field(default_factory=list)

    def reset(self, obj, gripper, rng) -> None:
        super().reset(obj, gripper, rng)
        self.inner.reset(obj, gripper, rng)
        self.starts = []

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        wrapped = []
        for proposal in self.inner.propose(n, rng):
            record = {**proposal.record, "start": len(self.starts)}
            self.starts.append(proposal)
            wrapped.append(Proposal(proposal.T_object_gripper, proposal.q, record))
        return wrapped

    def observe(self, outcomes: Sequence[Outcome]) -> None:
        self.inner.observe([Outcome(self.starts[o.proposal.record["start"]], o.error,
                                    o.collision_free, o.valid, o.holds) for o in outcomes])

    def in_flight_limit(self) -> int | None:
        return self.inner.in_flight_limit()

    def hears_quality(self) -> bool:
        return self.inner.hears_quality()


class PlannedStarts(NamedTuple):
    """The starts of one plan and what became of them, in the order of the plan's grasps.

    Attributes:
        surface: the object surface the plan matched against (its working surface), object
            frame.
        T_object_gripper: each sample's start, shape (M, 4, 4), metres.
        valid: :attr:`isf.Grasp.valid` of each sample's grasp, shape (M,).
        error: each grasp's fitting error, metres, shape (M,).
    """

    surface: ObjectSurface
    T_object_gripper: np.ndarray
    valid: np.ndarray
    error: np.ndarray

    def features(self, axes: GripperAxes) -> np.ndarray:
        """The features of each start (:func:`~isf_sampler_learned.features.candidate_features`
        on :attr:`surface` for a gripper with ``axes``), shape (M, F)."""
        T = self.T_object_gripper
        centres = T[:, :3, :3] @ axes.centre + T[:, :3, 3]
        return candidate_features(ObjectDescriptors.build(self.surface, axes), axes, centres,
                                  T[:, :3, :3])


def plan_starts(gripper, obj, sampler: str, *, samples: int = 60, seed: int = 0) -> PlannedStarts:
    """Plan ``obj`` (an :class:`isf.ObjectSurface`) with the sampler named ``sampler`` and keep
    each sample's start with its outcome."""
    import isf

    recorder = _RecordingSampler(inner=get_sampler(sampler, **SAMPLER_PARAMS.get(sampler, {})))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. objects larger than the opening
        result = isf.plan(gripper, obj, samples=samples, sampler=recorder, seed=seed)
    T = np.stack([recorder.starts[grasp.sampler_record["start"]].T_object_gripper
                  for grasp in result.grasps])
    return PlannedStarts(recorder.obj, T, np.array([g.valid for g in result.grasps], dtype=bool),
                         np.array([g.fit.mean_distance for g in result.grasps], dtype=float))


def collect_examples(gripper, objects: Sequence, *, samplers: Sequence[str] = ("uniform", "regret"),
                     samples: int = 60, seed: int = 0,
                     progress: Callable[[str], None] | None = None) -> Examples:
    """Plan every object with every sampler and label each sample's start.

    Args:
        gripper: an :class:`isf.Gripper`.
        objects: :class:`isf.ObjectSurface` objects or specs for :func:`isf.open_object`.
        samplers: names of the samplers that propose the starts.
        samples: samples per plan.
        seed: the k-th plan is seeded ``seed + k``.
        progress: called with a line per plan.
    """
    import isf

    axes = gripper_axes(gripper)
    rows, valid, error, group = [], [], [], []
    k = 0
    for g, spec in enumerate(objects):
        obj = spec if isinstance(spec, isf.ObjectSurface) else isf.open_object(spec)
        for name in samplers:
            planned = plan_starts(gripper, obj, name, samples=samples, seed=seed + k)
            k += 1
            rows.append(planned.features(axes))
            valid.extend(planned.valid)
            error.extend(planned.error)
            group.extend([g] * len(planned.valid))
            if progress is not None:
                progress(f"{obj.name} {name}: {int(planned.valid.sum())}/{samples} valid")
    return Examples(np.concatenate(rows), np.array(valid, dtype=bool), np.array(error, dtype=float),
                    np.array(group, dtype=int))


@dataclass(frozen=True)
class HeldOut:
    """Accuracy on objects left out of training.

    Attributes:
        accuracy: share of held-out starts whose validity the model predicts (p > 0.5).
        base_rate: share the majority label alone would predict.
        top_decile_valid: share of valid starts among the model's top 10 % held-out starts.
        valid_rate: share of valid starts among all held-out starts.
        examples: held-out starts.
        object_auc: mean over the held-out objects with both labels of the AUC of the model's
            ranking of that object's starts (0.5: no better than chance); None without such
            an object.
        object_top_decile_valid: mean over the held-out objects of the valid share among the
            top 10 % of that object's starts by the model.
        object_valid_rate: mean over the held-out objects of their valid share.
    """

    accuracy: float
    base_rate: float
    top_decile_valid: float
    valid_rate: float
    examples: int
    object_auc: float | None
    object_top_decile_valid: float
    object_valid_rate: float


def held_out_accuracy(examples: Examples, holdout: int, **fit_args) -> HeldOut | None:
    """Fit on the objects whose index is not a multiple of ``holdout`` - 1 ... and test on the
    others: every ``holdout``-th object (indices ``holdout - 1, 2 * holdout - 1, ...``) is left
    out. None when that leaves no object on one side."""
    test = examples.group % holdout == holdout - 1
    if not test.any() or test.all():
        return None
    model = fit_model(examples.features[~test], examples.valid[~test], examples.error[~test],
                      **fit_args)
    p = model.p_valid(examples.features[test])
    truth = examples.valid[test]
    top = p >= np.quantile(p, 0.9)
    rate = float(truth.mean())
    ranking = object_ranking(p, truth, examples.group[test])
    return HeldOut(accuracy=float(((p > 0.5) == truth).mean()), base_rate=max(rate, 1 - rate),
                   top_decile_valid=float(truth[top].mean()), valid_rate=rate,
                   examples=int(test.sum()), object_auc=ranking.auc,
                   object_top_decile_valid=ranking.top_decile_valid,
                   object_valid_rate=ranking.valid_rate)


class ObjectRanking(NamedTuple):
    """How well scores rank the starts within each object, averaged over the objects.

    Attributes:
        auc: mean over the objects with both labels of the probability that a valid start
            outscores an invalid one (0.5: chance); None without such an object.
        top_decile_valid: mean over the objects of the valid share of their top 10 % starts.
        valid_rate: mean over the objects of their valid share.
    """

    auc: float | None
    top_decile_valid: float
    valid_rate: float


def object_ranking(score: np.ndarray, valid: np.ndarray, group: np.ndarray) -> ObjectRanking:
    """The within-object ranking figures of ``score`` (M,) for labels ``valid`` (M,) of starts
    from objects ``group`` (M,)."""
    aucs, tops, rates = [], [], []
    for g in np.unique(group):
        mine = group == g
        auc = _auc(score[mine], valid[mine])
        if auc is not None:
            aucs.append(auc)
        best = np.argsort(-score[mine], kind="stable")[:max(1, round(0.1 * mine.sum()))]
        tops.append(valid[mine][best].mean())
        rates.append(valid[mine].mean())
    return ObjectRanking(float(np.mean(aucs)) if aucs else None, float(np.mean(tops)),
                         float(np.mean(rates)))


def _auc(score: np.ndarray, truth: np.ndarray) -> float | None:
    """The probability that a valid start outscores an invalid one (ties count half: the
    Mann-Whitney statistic over the pairs), or None when one label is missing."""
    from scipy.stats import mannwhitneyu

    truth = np.asarray(truth, dtype=bool)
    positives, negatives = score[truth], score[~truth]
    if not len(positives) or not len(negatives):
        return None
    return float(mannwhitneyu(positives, negatives).statistic / (len(positives) * len(negatives)))


def train(gripper, objects: Sequence, *, samplers: Sequence[str] = ("uniform", "regret"),
          samples: int = 60, seed: int = 0, holdout: int = 4, l2: float = L2,
          examples: Examples | None = None,
          progress: Callable[[str], None] | None = None) -> tuple[LearnedModel, HeldOut | None]:
    """Collect examples (:func:`collect_examples`), measure held-out figures and fit the model
    on all of them.

    Args:
        l2: the model's L2 penalty (:func:`~isf_sampler_learned.model.fit_model`).
        examples: examples collected before from the same objects, samplers, samples and seed
            (:meth:`Examples.load`); None: plan the objects now.

    Returns:
        the model (its ``info`` holds the objects, seed, counts and held-out figures) and the
        :class:`HeldOut` figures (None when there are too few objects to hold any out).
    """
    if examples is None:
        examples = collect_examples(gripper, objects, samplers=samplers, samples=samples,
                                    seed=seed, progress=progress)
    identity = dict(gripper_sha256=gripper_sha256(gripper), gripper_name=gripper.name)
    held = held_out_accuracy(examples, holdout, l2=l2, **identity)
    info = {
        "objects": [getattr(o, "name", str(o)) for o in objects],
        "samplers": list(samplers), "sampler_params": {name: SAMPLER_PARAMS[name] for name in
                                                       samplers if name in SAMPLER_PARAMS},
        "samples": samples, "seed": seed, "l2": l2,
        "examples": int(len(examples.valid)), "valid": int(examples.valid.sum()),
        "feature_version": FEATURE_VERSION, "features": list(FEATURE_NAMES),
        "held_out": None if held is None else held.__dict__.copy(),
    }
    model = fit_model(examples.features, examples.valid, examples.error, info=info, l2=l2,
                      **identity)
    return model, held
