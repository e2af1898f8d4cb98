"""The ``learned`` sampler: starts scored by a model trained on earlier ISF outcomes.

At :meth:`LearnedSampler.reset` it draws a pool of cheap candidate starts: ``candidates //
spins`` object points, each with ``spins`` orientations evenly spaced about the inward normal
(the gripper's approach axis facing the surface; uniformly random orientations for a gripper
without one). The model scores each from its features (:mod:`isf_sampler_learned.features`):

    prior(c) = logit P(valid | c) - error_weight * (predicted log10 error(c) - median) / spread

Each :meth:`~LearnedSampler.propose` draws an unused candidate with probability proportional
to ``exp(score / temperature)`` (the Gumbel-max trick on the plan's ``rng``), with a
temperature ``exploration * decay**t`` after ``t`` proposals: it spreads early and settles on
the best later. :meth:`~LearnedSampler.observe` updates the candidates' *region* (the nearest
of ``regions`` anchor points spread over the candidates), as the regret bandit updates a
cluster: a region's probability of success is the model's prior worth ``prior_strength``
pseudo-outcomes plus its observed outcomes (success: collision-free with a finite error), and
its expected log error mixes the prediction with the errors seen there.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from isf.exceptions import ConfigError
from isf.samplers import Outcome, Proposal, Sampler, place_gripper, random_rotation
from isf.samplers.orientation import facing_rotations
from isf.se3 import exp_so3

from .bundled import bundled_model
from .features import (
    GripperAxes,
    ObjectDescriptors,
    candidate_features,
    gripper_axes,
    gripper_sha256,
)
from .model import LearnedModel, load_model

if TYPE_CHECKING:
    from isf.gripper.model import Gripper
    from isf.object.surface import ObjectSurface

__all__ = ["LearnedSampler", "NoModelWarning"]

logger = logging.getLogger(__name__)
_TEMPERATURE_FLOOR = 1e-3
_CLIP = 1e-4  # probabilities are kept within [_CLIP, 1 - _CLIP] before the logit


class NoModelWarning(UserWarning):
    """``model="auto"`` found no bundled model for the gripper: proposals have no prior."""


@dataclass(eq=False, kw_only=True)
class LearnedSampler(Sampler):
    """Candidate starts ranked by a trained model, refined online by per-region outcomes.

    ``record`` holds ``{"candidate": index into the pool, "region": r, "p_valid": model's
    probability}``.

    Args:
        model: ``"auto"`` (default): the bundled model trained for this gripper (matched by
            :func:`~isf_sampler_learned.features.gripper_sha256`), or none with a
            :class:`NoModelWarning`; ``"none"``: no model (online evidence only); else the
            path of a model file (:mod:`isf_sampler_learned.model`), which must belong to the
            gripper.
        candidates: size of the candidate pool, >= 1.
        spins: orientations per candidate point, >= 1.
        exploration: temperature of the first draw (logit units), >= 0.
        decay: factor of the temperature per proposal, in (0, 1].
        prior_strength: pseudo-outcomes the model's prior is worth in a region, > 0.
        error_weight: weight of the predicted fitting error in the score, >= 0.
        regions: regions of online evidence, >= 1.

    Attributes:
        pool_centres: candidate grasp centres, object frame, shape (C, 3), metres.
        pool_T: candidate ``T_object_gripper``, shape (C, 4, 4).
        p_valid: the model's probability of a valid grasp per candidate, shape (C,).
        prior: the prior score per candidate, shape (C,).
        region: region of each candidate, shape (C,).
        successes: successes per region, shape (regions,).
        trials: outcomes per region, shape (regions,).
        used: whether each candidate was proposed, shape (C,).
    """

    name = "learned"
    description = "starts ranked by a model trained on earlier ISF outcomes, refined online"

    model: str | os.PathLike = "auto"
    candidates: int = 512
    spins: int = 8
    exploration: float = 0.5
    decay: float = 0.9
    prior_strength: float = 4.0
    error_weight: float = 0.5
    regions: int = 8

    loaded: LearnedModel | None = field(init=False, repr=False, default=None)
    pool_centres: np.ndarray = field(init=False, repr=False, default=None)
    pool_T: np.ndarray = field(init=False, repr=False, default=None)
    p_valid: np.ndarray = field(init=False, repr=False, default=None)
    prior: np.ndarray = field(init=False, repr=False, default=None)
    region: np.ndarray = field(init=False, repr=False, default=None)
    successes: np.ndarray = field(init=False, repr=False, default=None)
    trials: np.ndarray = field(init=False, repr=False, default=None)
    used: np.ndarray = field(init=False, repr=False, default=None)
    _log_error: np.ndarray = field(init=False, repr=False, default=None)
    _error_sum: np.ndarray = field(init=False, repr=False, default=None)
    _error_count: np.ndarray = field(init=False, repr=False, default=None)
    _proposed: int = field(init=False, repr=False, default=0)
    _axes: GripperAxes | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        for key in ("candidates", "spins", "regions"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ConfigError(f"learned: {key} must be an integer >= 1, got {value!r}")
        ranges = {"exploration": (0.0, np.inf, True), "decay": (0.0, 1.0, False),
                  "prior_strength": (0.0, np.inf, False), "error_weight": (0.0, np.inf, True)}
        for key, (low, high, closed) in ranges.items():
            value = getattr(self, key)
            number = isinstance(value, (int, float, np.number)) and not isinstance(value, bool)
            if not number or not np.isfinite(value) or not (
                    (low <= value if closed else low < value) and value <= high):
                bound = f"{'>=' if closed else '>'} {low}" + ("" if high == np.inf else
                                                             f" and <= {high}")
                raise ConfigError(f"learned: {key} must be a number {bound}, got {value!r}")
        if not isinstance(self.model, (str, os.PathLike)):
            raise ConfigError(f"learned: model must be 'auto', 'none' or a file path, "
                              f"got {self.model!r}")

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Score a fresh candidate pool on ``obj`` and forget earlier outcomes.

        Raises:
            ModelFileError: ``model`` names a file that is unreadable or made for another
                gripper or feature definition.
        """
        super().reset(obj, gripper, rng)
        self._axes = gripper_axes(gripper)
        self.loaded = self._resolve_model(gripper)
        n_points = max(1, min(self.candidates // self.spins, obj.n_points))
        index = np.sort(rng.choice(obj.n_points, size=n_points, replace=False))
        R = self._orientations(obj, index, rng)
        centres = np.repeat(obj.points[index], self.spins, axis=0)
        self.pool_centres = centres
        self.pool_T = place_gripper(gripper, centres, R)
        self._score(ObjectDescriptors.build(obj, self._axes), centres, R)
        self.region = np.repeat(_regions(obj.points[index], self.regions), self.spins)
        k = int(self.region.max()) + 1
        self.successes = np.zeros(k)
        self.trials = np.zeros(k)
        self._error_sum = np.zeros(k)
        self._error_count = np.zeros(k)
        self.used = np.zeros(len(centres), dtype=bool)
        self._proposed = 0

    def _resolve_model(self, gripper: Gripper) -> LearnedModel | None:
        """The model of ``self.model`` for ``gripper``, or None."""
        text = os.fspath(self.model)
        if text == "none":
            return None
        digest = gripper_sha256(gripper)
        if text != "auto":
            return load_model(text, gripper_sha256=digest)
        model = bundled_model(digest)
        if model is None:
            warnings.warn(
                f"learned: no bundled model for gripper {gripper.name!r}; proposing without a "
                "prior (train one with 'python -m isf_sampler_learned train' and pass "
                "model=FILE)", NoModelWarning, stacklevel=3)
        return model

    def _orientations(self, obj: ObjectSurface, index: np.ndarray,
                      rng: np.random.Generator) -> np.ndarray:
        """``spins`` orientations per point, (len(index) * spins, 3, 3)."""
        if self.gripper.approach is None:
            return random_rotation(rng, size=len(index) * self.spins)
        inward = -obj.normals[index]
        base = facing_rotations(self._axes.approach, inward, rng)  # a random first spin
        turns = 2.0 * np.pi * np.arange(self.spins) / self.spins
        unit = inward / np.linalg.norm(inward, axis=1, keepdims=True)
        return np.stack([exp_so3(turn * d) @ R for d, R in zip(unit, base) for turn in turns])

    def _score(self, descriptors: ObjectDescriptors, centres: np.ndarray,
               R: np.ndarray) -> None:
        """Set ``p_valid``, ``prior`` and the predicted log errors of the pool."""
        if self.loaded is None:
            self.p_valid = np.full(len(centres), 0.5)
            self._log_error = np.zeros(len(centres))
            self.prior = np.zeros(len(centres))
            return
        features = candidate_features(descriptors, self._axes, centres, R)
        self.p_valid = np.clip(self.loaded.p_valid(features), _CLIP, 1 - _CLIP)
        self._log_error = self.loaded.log_error(features)
        self.prior = _logit(self.p_valid) - self._error_penalty(self._log_error)

    def _error_penalty(self, log_error: np.ndarray) -> np.ndarray:
        spread = self.loaded.error_spread if self.loaded is not None else 1.0
        return self.error_weight * (log_error - np.median(self._log_error)) / spread

    def scores(self) -> np.ndarray:
        """Current score of every candidate: the prior refined by its region's outcomes,
        shape (C,)."""
        self._require_reset()
        r = self.region
        a = self.prior_strength
        p = (a * self.p_valid + self.successes[r]) / (a + self.trials[r])
        log_error = (a * self._log_error + self._error_sum[r]) / (a + self._error_count[r])
        penalty = self._error_penalty(log_error) if self.loaded is not None else 0.0
        return _logit(np.clip(p, _CLIP, 1 - _CLIP)) - penalty

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """``n`` unused candidates drawn by their scores at the current temperature (the pool
        is reused once every candidate was proposed)."""
        _, gripper = self._require_reset()
        proposals = []
        for _ in range(n):
            if self.used.all():
                self.used[:] = False
            temperature = max(self.exploration * self.decay**self._proposed, _TEMPERATURE_FLOOR)
            noisy = self.scores() / temperature + rng.gumbel(size=len(self.used))
            i = int(np.argmax(np.where(self.used, -np.inf, noisy)))
            self.used[i] = True
            self._proposed += 1
            record = {"candidate": i, "region": int(self.region[i]),
                      "p_valid": float(self.p_valid[i])}
            proposals.append(Proposal(self.pool_T[i], record=record))
        return proposals

    def observe(self, outcomes: Sequence[Outcome]) -> None:
        """Fold each outcome into its candidate's region.

        Raises:
            ValueError: an outcome's proposal has no valid ``"candidate"`` record.
        """
        self._require_reset()
        for outcome in outcomes:
            i = outcome.proposal.record.get("candidate")
            if not isinstance(i, (int, np.integer)) or not 0 <= i < len(self.used):
                raise ValueError(
                    f"learned: outcome record {dict(outcome.proposal.record)!r} has no valid "
                    "'candidate'; pass back proposals made by this sampler since reset()")
            r = self.region[i]
            success = outcome.collision_free and np.isfinite(outcome.error)
            self.trials[r] += 1
            self.successes[r] += success
            if success and outcome.error > 0:
                self._error_sum[r] += np.log10(outcome.error)
                self._error_count[r] += 1


def _logit(p: np.ndarray) -> np.ndarray:
    return np.log(p) - np.log1p(-p)


def _regions(points: np.ndarray, k: int) -> np.ndarray:
    """Region of each point: its nearest of ``k`` anchors chosen by farthest-point sampling
    from the first point (deterministic), shape (len(points),)."""
    k = min(k, len(points))
    anchors = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    for _ in range(k - 1):
        anchors.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[anchors[-1]], axis=1))
    gaps = np.linalg.norm(points[:, None, :] - points[anchors][None, :, :], axis=2)
    return np.argmin(gaps, axis=1)
