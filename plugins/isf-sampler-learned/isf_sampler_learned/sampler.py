"""The ``learned`` sampler: the regret bandit's arms, chosen by a validity posterior whose prior
is a model trained on earlier ISF outcomes.

The arms are the regret sampler's (:class:`isf.samplers.regret.RegretSampler`): k-means
cluster centres of the object's points, each approached against its cluster's mean inward
normal, plus ``model_arms`` surface points that the model ranks best among ``pool`` random
ones (at least one opening apart) on a surface of one major piece (an object,
:attr:`~isf_sampler_learned.features.ObjectDescriptors.major_pieces`). On a surface of several
(a scene of separate objects) the model's arms are left out unless ``clutter_model_arms``: the
model judges a start by the piece under it alone, blind to the neighbours around it, so its
best-ranked points there are no better bets than the cluster centres (measured in
docs/sampler-learned.md); the model still scores every cluster arm's spins. At
:meth:`LearnedSampler.reset` the model scores ``spins`` orientations per arm (evenly spaced
about the arm's inward direction, the gripper's approach axis facing the surface; uniformly
random ones for a gripper without an approach):

    score = logit P(valid) - error_weight * (predicted log10 error - median) / spread

and an arm's *prior* ``pi`` is the mean ``P(valid)`` of its ``top`` best-scored spins. Each
:meth:`~LearnedSampler.propose`:

- picks the arm by Thompson sampling of a Beta posterior of its validity,
  ``Beta(n0 pi + valid, n0 (1 - pi) + invalid)`` with ``n0 = prior_strength`` (proposals
  still in flight count as invalid), less ``arm_error_weight`` times the arm's mean fitting
  error of its valid grasps relative to that of all valid grasps so far: the model decides
  the first samples, the outcomes take over as they arrive, and the exploration decays as
  the posteriors narrow (an arm the model ranks low is still drawn now and then);
- draws the arm's orientation with probability proportional to
  ``exp((score + spin_evidence * (valid - invalid outcomes of that spin)) / exploration)``
  (Gumbel-max on the plan's ``rng``), turned by a uniform angle within its spin's share of
  the circle so that repeated draws differ.

:meth:`~LearnedSampler.observe` counts each outcome's validity (``Outcome.valid``, the
planner's ``isf.Grasp.valid``) for its arm and spin and updates the regret bandit's table
too. Without a model the sampler is the regret sampler with evenly spread spins.
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
from isf.samplers import (
    Outcome,
    Proposal,
    Sampler,
    flag_parameter,
    integer_parameter,
    number_parameter,
    place_gripper,
)
from isf.samplers.orientation import initial_rotations
from isf.samplers.regret import RegretSampler
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
_CLIP = 1e-4  # probabilities are kept within [_CLIP, 1 - _CLIP] before the logit
_POOL_SPINS = 6  # orientations per pool point when choosing the model's arms
_BETA_FLOOR = 1e-3  # least Beta parameter (a prior_strength of 0 leaves untried arms at 0)


class NoModelWarning(UserWarning):
    """``model="auto"`` found no bundled model for the gripper: proposals have no prior."""


@dataclass(eq=False, kw_only=True)
class LearnedSampler(Sampler):
    """The regret bandit's arms, ordered and oriented by a trained model (module docstring).

    ``record`` holds ``{"cluster": arm, "regret": its average regret when proposed,
    "spin": orientation index, "p_valid": the model's probability}``; arms
    ``0 .. k_clusters - 1`` are the k-means clusters, the others the model's arms.

    Args:
        model: ``"auto"`` (default): the bundled model trained for this gripper (matched by
            :func:`~isf_sampler_learned.features.gripper_sha256`), or none with a
            :class:`NoModelWarning`; ``"none"``: no model (the regret sampler with
            evenly spread spins); else the path of a model file
            (:mod:`isf_sampler_learned.model`), which must belong to the gripper.
        spins: orientations the model scores per arm, >= 1.
        exploration: temperature of the orientation draw (logit units), >= 0 (0: always the
            best-scored spin).
        error_weight: weight of the predicted fitting error in the score, >= 0.
        model_arms: arms added at the model's best surface points, >= 0.
        clutter_model_arms: add them also on a surface of several major pieces (a scene).
        pool: random surface points scored to place those arms, >= 1.
        top: best spins averaged into an arm's prior, >= 1.
        prior_strength: how many outcomes the model's prior of an arm is worth, >= 0.
        spin_evidence: logit units a spin's score gains per valid outcome there (and loses
            per invalid one), >= 0.
        arm_error_weight: weight of an arm's relative fitting error in its choice, >= 0.
        n_clusters: k-means clusters (the regret sampler's ``n_clusters``; None: its default).
        gamma: collision penalty factor of the regret update (the regret sampler's), >= 0.

    Attributes:
        bandit: the regret sampler that keeps the arms (its ``centres``, ``inward``,
            ``regret``, ``trials`` and ``pending`` include the model's arms).
        k_clusters: how many of the arms are k-means clusters.
        R: orientations per arm, ``R_object_gripper``, shape (A, spins, 3, 3).
        p_valid: the model's probability of a valid grasp per arm and spin, shape (A, spins).
        score: score per arm and spin, shape (A, spins).
        prior_valid: the model's prior validity per arm, shape (A,).
        used: whether each arm's spin was proposed, shape (A, spins) (a gripper without an
            approach draws each of its arm's random rotations once before any twice).
        hits: valid outcomes per arm, shape (A,).
        valid_error: summed fitting error of each arm's valid outcomes, metres, shape (A,).
        evidence: valid minus invalid outcomes per arm and spin, shape (A, spins).
    """

    name = "learned"
    description = "regret's arms and spins, chosen by validity posteriors with a trained model as prior"

    model: str | os.PathLike = "auto"
    spins: int = 12
    exploration: float = 0.5
    error_weight: float = 0.5
    model_arms: int = 4
    clutter_model_arms: bool = False
    pool: int = 48
    top: int = 3
    prior_strength: float = 2.0
    spin_evidence: float = 1.0
    arm_error_weight: float = 0.5
    n_clusters: int | None = None
    gamma: float = 0.2

    loaded: LearnedModel | None = field(init=False, repr=False, default=None)
    bandit: RegretSampler = field(init=False, repr=False, default=None)
    k_clusters: int = field(init=False, repr=False, default=0)
    R: np.ndarray = field(init=False, repr=False, default=None)
    p_valid: np.ndarray = field(init=False, repr=False, default=None)
    score: np.ndarray = field(init=False, repr=False, default=None)
    prior_valid: np.ndarray = field(init=False, repr=False, default=None)
    used: np.ndarray = field(init=False, repr=False, default=None)
    hits: np.ndarray = field(init=False, repr=False, default=None)
    valid_error: np.ndarray = field(init=False, repr=False, default=None)
    evidence: np.ndarray = field(init=False, repr=False, default=None)
    _axes: GripperAxes | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        for key, low in (("spins", 1), ("model_arms", 0), ("pool", 1), ("top", 1)):
            setattr(self, key, integer_parameter(getattr(self, key), "learned", key, low))
        for key in ("exploration", "error_weight", "prior_strength", "spin_evidence",
                    "arm_error_weight"):
            setattr(self, key, number_parameter(getattr(self, key), "learned", key))
        self.clutter_model_arms = flag_parameter(self.clutter_model_arms, "learned",
                                                 "clutter_model_arms")
        if not isinstance(self.model, (str, os.PathLike)):
            raise ConfigError(f"learned: model must be 'auto', 'none' or a file path, "
                              f"got {self.model!r}")
        RegretSampler(n_clusters=self.n_clusters, gamma=self.gamma, com_share=0)  # validates both

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Cluster the object, place the model's arms, score every arm's spins and zero the
        outcome counts.

        Raises:
            ModelFileError: ``model`` names a file that is unreadable or made for another
                gripper or feature definition.
            ConfigError: the object has fewer points than the clusters.
        """
        super().reset(obj, gripper, rng)
        self._axes = gripper_axes(gripper)
        self.loaded = self._resolve_model(gripper)
        self.bandit = RegretSampler(n_clusters=self.n_clusters, gamma=self.gamma, com_share=0)
        self.bandit.reset(obj, gripper, rng)
        self.k_clusters = self.bandit.k
        descriptors = None if self.loaded is None else ObjectDescriptors.build(obj, self._axes)
        if descriptors is not None and self.model_arms and (
                self.clutter_model_arms or descriptors.major_pieces == 1):
            self._add_model_arms(obj, descriptors, rng)
        bandit = self.bandit
        R = self._spin_rotations(bandit.inward, self.spins, rng)
        self.R = R.reshape(bandit.k, self.spins, 3, 3)
        if descriptors is None:
            self.p_valid = np.full((bandit.k, self.spins), 0.5)
            self.score = np.zeros((bandit.k, self.spins))
        else:
            centres = np.repeat(bandit.centres, self.spins, axis=0)
            p_valid, score = self._score(descriptors, centres, R)
            self.p_valid = p_valid.reshape(bandit.k, self.spins)
            self.score = score.reshape(bandit.k, self.spins)
        top = min(self.top, self.spins)
        best = np.argsort(self.score, axis=1)[:, -top:]
        self.prior_valid = np.take_along_axis(self.p_valid, best, axis=1).mean(axis=1)
        self.used = np.zeros((bandit.k, self.spins), dtype=bool)
        self.hits = np.zeros(bandit.k)
        self.valid_error = np.zeros(bandit.k)
        self.evidence = np.zeros((bandit.k, self.spins))

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

    def _spin_rotations(self, inward: np.ndarray, spins: int,
                        rng: np.random.Generator) -> np.ndarray:
        """``spins`` orientations per inward direction, evenly spaced about it from a random
        first one (random rotations for a gripper without an approach), (len(inward) * spins,
        3, 3)."""
        if self.gripper.approach is None:
            return initial_rotations(None, np.repeat(inward, spins, axis=0), rng)
        unit = inward / np.linalg.norm(inward, axis=1, keepdims=True)
        base = initial_rotations(self._axes.approach, unit, rng)
        turns = _turns(unit, 2.0 * np.pi * np.arange(spins) / spins)  # (A, spins, 3, 3)
        return (turns @ base[:, None]).reshape(-1, 3, 3)

    def _score(self, descriptors: ObjectDescriptors, centres: np.ndarray,
               R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The model's ``P(valid)`` and score of starts (centres (M, 3), R (M, 3, 3)), each
        shape (M,)."""
        features = candidate_features(descriptors, self._axes, centres, R)
        p_valid = np.clip(self.loaded.p_valid(features), _CLIP, 1 - _CLIP)
        log_error = self.loaded.log_error(features)
        penalty = self.error_weight * (log_error - np.median(log_error)) / self.loaded.error_spread
        return p_valid, _logit(p_valid) - penalty

    def _add_model_arms(self, obj: ObjectSurface, descriptors: ObjectDescriptors,
                        rng: np.random.Generator) -> None:
        """Append to the bandit's arms the ``model_arms`` best of ``pool`` random surface points
        (by the mean of their ``top`` best spin scores), at least one opening apart."""
        index = rng.choice(obj.n_points, size=min(self.pool, obj.n_points), replace=False)
        points, inward = obj.points[index], -obj.normals[index]
        R = self._spin_rotations(inward, _POOL_SPINS, rng)
        _, score = self._score(descriptors, np.repeat(points, _POOL_SPINS, axis=0), R)
        top = min(self.top, _POOL_SPINS)
        merit = np.sort(score.reshape(len(index), _POOL_SPINS), axis=1)[:, -top:].mean(axis=1)
        chosen: list[int] = []
        for j in np.argsort(-merit, kind="stable"):
            if all(np.linalg.norm(points[j] - points[c]) > self._axes.opening for c in chosen):
                chosen.append(int(j))
            if len(chosen) == self.model_arms:
                break
        bandit = self.bandit
        bandit.centres = np.vstack([bandit.centres, points[chosen]])
        bandit.inward = np.vstack([bandit.inward, inward[chosen]])
        bandit.k += len(chosen)
        bandit.regret = np.zeros(bandit.k)
        bandit.trials = np.zeros(bandit.k, dtype=int)
        bandit.pending = np.zeros(bandit.k, dtype=int)

    def choose_arm(self, rng: np.random.Generator) -> int:
        """The arm of the next proposal: a Thompson draw of each arm's validity posterior less
        its relative fitting error (module docstring); without a model, the regret bandit's
        choice."""
        self._require_reset()
        bandit = self.bandit
        if self.loaded is None:
            return bandit.best_cluster()
        n0 = self.prior_strength
        misses = bandit.trials + bandit.pending - self.hits
        value = rng.beta(np.maximum(n0 * self.prior_valid + self.hits, _BETA_FLOOR),
                         np.maximum(n0 * (1.0 - self.prior_valid) + misses, _BETA_FLOOR))
        found = self.hits.sum()
        if found and self.arm_error_weight:
            overall = max(self.valid_error.sum() / found, 1e-12)
            mean = np.where(self.hits > 0, self.valid_error / np.maximum(self.hits, 1), overall)
            value = value - self.arm_error_weight * (mean / overall - 1.0)
        return int(np.argmax(value))

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """``n`` proposals, each at the arm :meth:`choose_arm` gives with an orientation drawn
        by its spins' scores."""
        _, gripper = self._require_reset()
        bandit = self.bandit
        proposals = []
        for _ in range(n):
            k = self.choose_arm(rng)
            noisy = self.score[k] + self.spin_evidence * self.evidence[k]
            if self.exploration > 0:
                noisy = noisy / self.exploration + rng.gumbel(size=self.spins)
            if gripper.approach is None:  # a fixed set of random rotations: each once per round
                if self.used[k].all():
                    self.used[k] = False
                noisy = np.where(self.used[k], -np.inf, noisy)
            i = int(np.argmax(noisy))
            self.used[k, i] = True
            R = self.R[k, i]
            if gripper.approach is not None:
                axis = bandit.inward[k] / np.linalg.norm(bandit.inward[k])
                R = exp_so3(rng.uniform(-np.pi, np.pi) / self.spins * axis) @ R
            record = {"cluster": k, "regret": float(bandit.regret[k]), "spin": i,
                      "p_valid": float(self.p_valid[k, i])}
            bandit.pending[k] += 1
            proposals.append(Proposal(place_gripper(gripper, bandit.centres[k], R),
                                      record=record))
        return proposals

    def in_flight_limit(self) -> int | None:
        """Without a model the regret bandit's (one proposal per untried arm while some are
        untried); with one, no limit (proposals in flight count as invalid in the draw)."""
        self._require_reset()
        return self.bandit.in_flight_limit() if self.loaded is None else None

    def observe(self, outcomes: Sequence[Outcome]) -> None:
        """Count each outcome's validity (``Outcome.valid``) for its arm and spin, and fold it
        into the arm's average regret (the regret sampler's update).

        Raises:
            ValueError: an outcome's proposal has no valid ``"cluster"`` record.
        """
        self._require_reset()
        try:
            self.bandit.observe(outcomes)
        except ValueError as err:
            raise ValueError(str(err).replace("regret:", "learned:", 1)) from None
        for outcome in outcomes:
            record = outcome.proposal.record
            k, i = record["cluster"], record.get("spin")
            if outcome.valid:
                self.hits[k] += 1
                self.valid_error[k] += outcome.error
            if isinstance(i, (int, np.integer)) and 0 <= i < self.spins:
                self.evidence[k, i] += 1.0 if outcome.valid else -1.0


def _logit(p: np.ndarray) -> np.ndarray:
    return np.log(p) - np.log1p(-p)


def _turns(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations by each of ``angles`` (S,) about each unit axis of ``axes`` (A, 3), shape
    (A, S, 3, 3) (Rodrigues' formula)."""
    K = np.zeros((len(axes), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    K -= K.transpose(0, 2, 1)
    sin, cos = np.sin(angles)[None, :, None, None], np.cos(angles)[None, :, None, None]
    return np.eye(3) + sin * K[:, None] + (1.0 - cos) * (K @ K)[:, None]
