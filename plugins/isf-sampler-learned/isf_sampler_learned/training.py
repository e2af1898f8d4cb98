"""Training data from isf's own plans, and the model fitted to it.

Every sample of a plan is an example: its start (the proposal's pose), described by
:func:`~isf_sampler_learned.features.candidate_features` on the surface the plan matched
against, and its outcome: ``valid`` (:attr:`isf.Grasp.valid`: collision-free and every
contact surface touching) and the fitting error (:attr:`isf.FitResult.mean_distance`,
metres). The plans run the existing samplers (``uniform`` and ``regret`` by default), seeded
``seed + k`` for the k-th plan, so the examples, and the model, are the same for a seed.

Held-out accuracy is measured on whole objects the model did not see: every
``holdout``-th object (in the order given) is left out of a first fit and classified by it;
the model written is then fitted on all objects.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from isf.samplers import Outcome, Proposal, Sampler, get_sampler

from .features import (
    FEATURE_NAMES,
    FEATURE_VERSION,
    ObjectDescriptors,
    candidate_features,
    gripper_axes,
    gripper_sha256,
)
from .model import LearnedModel, fit_model

__all__ = ["Examples", "HeldOut", "collect_examples", "held_out_accuracy", "train"]

logger = logging.getLogger(__name__)


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
                                    o.collision_free) for o in outcomes])

    def in_flight_limit(self) -> int | None:
        return self.inner.in_flight_limit()


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
            recorder = _RecordingSampler(inner=get_sampler(name))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # e.g. objects larger than the opening
                result = isf.plan(gripper, obj, samples=samples, sampler=recorder, seed=seed + k)
            k += 1
            descriptors = ObjectDescriptors.build(recorder.obj, axes)
            T = np.stack([recorder.starts[grasp.sampler_record["start"]].T_object_gripper
                          for grasp in result.grasps])
            centres = T[:, :3, :3] @ axes.centre + T[:, :3, 3]
            rows.append(candidate_features(descriptors, axes, centres, T[:, :3, :3]))
            valid.extend(grasp.valid for grasp in result.grasps)
            error.extend(grasp.fit.mean_distance for grasp in result.grasps)
            group.extend([g] * len(result.grasps))
            if progress is not None:
                progress(f"{obj.name} {name}: {result.stats.valid}/{samples} valid")
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
    """

    accuracy: float
    base_rate: float
    top_decile_valid: float
    valid_rate: float
    examples: int


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
    return HeldOut(accuracy=float(((p > 0.5) == truth).mean()), base_rate=max(rate, 1 - rate),
                   top_decile_valid=float(truth[top].mean()), valid_rate=rate,
                   examples=int(test.sum()))


def train(gripper, objects: Sequence, *, samplers: Sequence[str] = ("uniform", "regret"),
          samples: int = 60, seed: int = 0, holdout: int = 4,
          progress: Callable[[str], None] | None = None) -> tuple[LearnedModel, HeldOut | None]:
    """Collect examples (:func:`collect_examples`), measure held-out accuracy and fit the model
    on all of them.

    Returns:
        the model (its ``info`` holds the objects, seed, counts and held-out figures) and the
        :class:`HeldOut` figures (None when there are too few objects to hold any out).
    """
    examples = collect_examples(gripper, objects, samplers=samplers, samples=samples, seed=seed,
                                progress=progress)
    identity = dict(gripper_sha256=gripper_sha256(gripper), gripper_name=gripper.name)
    held = held_out_accuracy(examples, holdout, **identity)
    info = {
        "objects": [getattr(o, "name", str(o)) for o in objects],
        "samplers": list(samplers), "samples": samples, "seed": seed,
        "examples": int(len(examples.valid)), "valid": int(examples.valid.sum()),
        "feature_version": FEATURE_VERSION, "features": list(FEATURE_NAMES),
        "held_out": None if held is None else held.__dict__.copy(),
    }
    model = fit_model(examples.features, examples.valid, examples.error, info=info, **identity)
    return model, held
