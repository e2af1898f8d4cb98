"""The ``regret`` sampler: k-means cluster centres ranked by average regret (paper Alg. 3).

The object's points are split into K clusters by k-means; each cluster centre
is a candidate grasp centre, like an arm of a multi-armed bandit. Each round
samples the cluster with the lowest average regret (ties to the lowest index),
with a random orientation, and the fitted result updates that cluster:

.. math::

    regret(k^*) \\leftarrow \\frac{regret(k^*) \\, trial(k^*) + error}{trial(k^*) + 1},
    \\qquad regret(k^*) \\leftarrow (1 + \\gamma \\, col) \\, regret(k^*),
    \\qquad trial(k^*) \\leftarrow trial(k^*) + 1

with ``col = 1`` when the fitted gripper collides with the object. Starting
from ``regret = 0``, every cluster is tried once before any is tried twice
(as long as errors are positive).

With ``hear_quality=True`` (in a plan ranked by quality) a valid grasp that the quality ranking
does not expect to hold (:attr:`isf.samplers.Outcome.holds` False) counts as
``NO_CONTACT_ERROR``, like a fit whose contact surfaces do not all touch, so the bandit turns
to clusters whose grasps hold; measured in docs/samplers.md, off by default.

Besides the clusters, a share ``com_share`` of the proposals (every second one at the default
0.5; none on a scene) puts the grasp centre at the object's centre of mass, facing a uniformly
random direction: grasps whose contacts surround the centre of mass resist gravity best
(docs/validate.md), and a start on a cluster centre, on the surface, seldom converges there on
a large object. These starts update no cluster. ``com_share=0`` is the paper's Algorithm 3.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ConfigError
from .base import (
    NO_CONTACT_ERROR,
    Outcome,
    Proposal,
    Sampler,
    flag_parameter,
    integer_parameter,
    number_parameter,
    place_gripper,
)
from .orientation import check_orientation, initial_rotations, resolve_approach

if TYPE_CHECKING:
    from ..gripper.model import Gripper
    from ..object.surface import ObjectSurface

__all__ = ["RegretSampler"]

logger = logging.getLogger(__name__)

_KMEANS_ATTEMPTS = 5
PAPER_CLUSTERS = 6
"""The paper's number of k-means centres (section V-A)."""
MAX_SCENE_CLUSTERS = 30
"""Most centres the default gives a scene."""
CENTRE_OF_MASS_START = "centre_of_mass"
"""The ``record["start"]`` of a proposal whose grasp centre is the object's centre of mass."""


def _default_clusters(obj: ObjectSurface, gripper: Gripper) -> int:
    """The default K: :data:`PAPER_CLUSTERS` on an object; on a scene one per square patch half
    as wide as the gripper's opening (the distance between its contact surfaces' centroids),
    from the surface's area (points times spacing squared), within [6, 30]."""
    if obj.viewpoints is None:
        return PAPER_CLUSTERS
    points, _ = gripper.contact_points(gripper.q_initial)
    centroids = np.array([points[gripper.point_surface == k].mean(axis=0)
                          for k in range(len(gripper.surfaces))])
    opening = float(np.ptp(centroids, axis=0).max()) if len(centroids) > 1 else 0.05
    area = obj.n_points * obj.spacing**2
    return int(np.clip(round(area / (0.5 * opening) ** 2), PAPER_CLUSTERS, MAX_SCENE_CLUSTERS))


@dataclass(eq=False, kw_only=True)
class RegretSampler(Sampler):
    """Guided sampling over k-means cluster centres (paper Alg. 3).

    The paper's loop proposes one grasp at a time (``propose(1)`` then
    ``observe``); ``propose(n)`` with ``n > 1`` gives ``n`` proposals at the
    current best cluster, each with its own random orientation. When proposals
    are still in flight (a planner fitting several samples at once), ties in
    regret go to the cluster with the fewest proposals awaiting an outcome, so
    the first round still spreads over the clusters. ``record``
    holds ``{"cluster": k, "regret": regret(k) when proposed}``.

    Args:
        n_clusters: number of k-means centres K, >= 1 and at most the number of object
            points; None (default): the paper's 6 on an object, and on what cameras saw (a
            scene, :mod:`isf.scene`) one per patch of the surface half as wide as the
            gripper's opening, at least 6 and at most 30 (``MAX_SCENE_CLUSTERS``).
        gamma: collision penalty factor (paper: 0.2), >= 0.
        kmeans_iterations: Lloyd iterations of k-means, >= 1.
        orientation: ``auto`` (default: the gripper's approach axis against the cluster's
            mean outward normal when it declares one, else random), ``approach`` or
            ``random`` (uniform on SO(3), the paper's); see :mod:`isf.samplers.orientation`.
        com_share: share of the proposals, in [0, 1), whose grasp centre is the object's
            centre of mass (:func:`isf.quality.grasp_quality.object_properties`: the solid's
            for a closed mesh), the approach axis on a uniformly random direction (a uniformly
            random orientation with ``orientation="random"``); proposal ``i`` (from 0) is one
            when ``floor((i + 1) * com_share) > floor(i * com_share)``. A scene
            (:mod:`isf.scene`, ``ObjectSurface.viewpoints`` set) gets none: the centroid of an
            unsegmented scene is the centre of mass of no object. 0 gives the paper's
            Algorithm 3.
        hear_quality: ask the planner for the quality ranking's verdict on each valid grasp
            (:meth:`hears_quality`) and count a valid grasp it does not expect to hold as
            ``NO_CONTACT_ERROR`` in its cluster's regret.

    Attributes:
        k: the number of centres K in use (``n_clusters`` or its default).
        centres: cluster centres, object frame, shape (K, 3), metres.
        labels: cluster of each object point, shape (N,).
        regret: average regret per cluster, shape (K,), metres.
        trials: number of outcomes per cluster, shape (K,).
        pending: proposals per cluster still awaiting an outcome, shape (K,).
        centre_of_mass: where the centre-of-mass starts put the grasp centre, object frame,
            shape (3,), metres; None when this plan makes none.
    """

    name = "regret"
    description = "k-means cluster centres chosen by least average fitting error (paper Alg. 3)"

    n_clusters: int | None = None
    gamma: float = 0.2
    kmeans_iterations: int = 10
    orientation: str = "auto"
    com_share: float = 0.5
    hear_quality: bool = False

    k: int = field(init=False, repr=False, default=0)
    centres: np.ndarray = field(init=False, repr=False, default=None)
    labels: np.ndarray = field(init=False, repr=False, default=None)
    regret: np.ndarray = field(init=False, repr=False, default=None)
    trials: np.ndarray = field(init=False, repr=False, default=None)
    inward: np.ndarray = field(init=False, repr=False, default=None)
    pending: np.ndarray = field(init=False, repr=False, default=None)
    centre_of_mass: np.ndarray | None = field(init=False, repr=False, default=None)
    _proposed: int = field(init=False, repr=False, default=0)
    _approach: np.ndarray | None = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        if self.n_clusters is not None:
            self.n_clusters = integer_parameter(self.n_clusters, "regret", "n_clusters", 1)
        self.kmeans_iterations = integer_parameter(self.kmeans_iterations, "regret",
                                                   "kmeans_iterations", 1)
        self.gamma = number_parameter(self.gamma, "regret", "gamma")
        self.com_share = number_parameter(self.com_share, "regret", "com_share", below=1.0)
        self.hear_quality = flag_parameter(self.hear_quality, "regret", "hear_quality")
        check_orientation(self.orientation, self.name)

    def reset(self, obj: ObjectSurface, gripper: Gripper, rng: np.random.Generator) -> None:
        """Cluster the object's points and zero the regret table (see :meth:`Sampler.reset`).

        Raises:
            ConfigError: the object has fewer points than ``n_clusters``.
        """
        super().reset(obj, gripper, rng)
        self.k = self.n_clusters if self.n_clusters is not None else \
            _default_clusters(obj, gripper)
        if obj.n_points < self.k:
            raise ConfigError(
                f"regret: n_clusters={self.k} exceeds the object's {obj.n_points} "
                "points; lower n_clusters or sample the object more densely"
            )
        self.centres = self._kmeans(obj.points, rng)
        from scipy.cluster.vq import vq  # scipy loads when a plan starts, not with the registry

        # kmeans2's labels predate its last centroid update; label by the final centres.
        self.labels = vq(obj.points, self.centres, check_finite=False)[0]
        self.regret = np.zeros(self.k)
        self.trials = np.zeros(self.k, dtype=int)
        self.pending = np.zeros(self.k, dtype=int)
        self._approach = resolve_approach(self.orientation, gripper, self.name)
        self.inward = self._inward_directions(obj)
        self._proposed = 0
        self.centre_of_mass = None
        if self.com_share > 0 and obj.viewpoints is None:
            from ..quality import object_properties

            self.centre_of_mass = object_properties(obj).center_of_mass

    def _inward_directions(self, obj: ObjectSurface) -> np.ndarray:
        """Per cluster, minus its points' mean normal (or the normal nearest its centre when
        the normals cancel, as on a thin part), shape (K, 3)."""
        inward = np.zeros((self.k, 3))
        np.add.at(inward, self.labels, -obj.normals)
        norm = np.linalg.norm(inward, axis=1)
        weak = norm < 0.3 * np.bincount(self.labels, minlength=self.k)
        if weak.any():
            _, nearest = obj.nearest(self.centres[weak])
            inward[weak] = -obj.normals[nearest]
        return inward

    def _kmeans(self, points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """k-means++ centres, shape (K, 3); retries when a cluster empties."""
        from scipy.cluster.vq import ClusterError, kmeans2

        for attempt in range(_KMEANS_ATTEMPTS):
            try:
                centres, _ = kmeans2(
                    points,
                    self.k,
                    iter=self.kmeans_iterations,
                    minit="++",
                    missing="raise",
                    seed=rng,
                )
                return np.asarray(centres, dtype=float)
            except ClusterError:
                logger.debug("k-means attempt %d left a cluster empty; retrying", attempt + 1)
        raise ConfigError(
            f"regret: k-means could not find {self.k} non-empty clusters in "
            f"{_KMEANS_ATTEMPTS} attempts (duplicate points?); lower n_clusters"
        )

    def best_cluster(self) -> int:
        """Index of the cluster with the least average regret (on ties: fewest proposals in
        flight, then the lowest index)."""
        self._require_reset()
        return int(np.lexsort((np.arange(self.k), self.pending, self.regret))[0])

    def propose(self, n: int, rng: np.random.Generator) -> list[Proposal]:
        """``n`` proposals, each with its own orientation: at the best cluster centre, or at the
        centre of mass where ``com_share`` asks for one."""
        _, gripper = self._require_reset()
        at_centre = [self._centre_of_mass_turn() for _ in range(n)]
        proposals: list[Proposal | None] = [None] * n
        n_centre = sum(at_centre)
        if n_centre < n:
            k = self.best_cluster()
            count = n - n_centre
            R = initial_rotations(self._approach, np.repeat(self.inward[k][None], count, axis=0),
                                  rng)
            T = place_gripper(gripper, self.centres[k], R)
            record = {"cluster": k, "regret": float(self.regret[k])}
            self.pending[k] += count
            slots = [i for i in range(n) if not at_centre[i]]
            for i, T_i in zip(slots, T):
                proposals[i] = Proposal(T_i, record=record)
        if n_centre:
            directions = rng.standard_normal((n_centre, 3))
            R = initial_rotations(self._approach, directions, rng)
            T = place_gripper(gripper, self.centre_of_mass, R)
            slots = [i for i in range(n) if at_centre[i]]
            for i, T_i in zip(slots, T):
                proposals[i] = Proposal(T_i, record={"start": CENTRE_OF_MASS_START})
        return proposals

    def _centre_of_mass_turn(self) -> bool:
        """Whether the next proposal starts at the centre of mass (advances the count)."""
        i = self._proposed
        self._proposed += 1
        if self.centre_of_mass is None:
            return False
        return math.floor((i + 1) * self.com_share) > math.floor(i * self.com_share)

    def hears_quality(self) -> bool:
        """``hear_quality``: whether the planner reports :attr:`Outcome.holds`."""
        return bool(self.hear_quality)

    def in_flight_limit(self) -> int | None:
        """While some cluster has no outcome yet, one proposal per such cluster (exploration,
        as the sequential loop does it); afterwards no limit."""
        self._require_reset()
        untried = int(np.count_nonzero(self.trials == 0))
        return max(untried, 1) if untried else None

    def observe(self, outcomes: Sequence[Outcome]) -> None:
        """Fold each outcome into its cluster's average regret, in order (a start at the centre
        of mass updates no cluster).

        Raises:
            ValueError: an outcome's proposal has neither a valid ``"cluster"`` record nor a
                centre-of-mass one.
        """
        self._require_reset()
        for outcome in outcomes:
            if outcome.proposal.record.get("start") == CENTRE_OF_MASS_START:
                continue
            k = outcome.proposal.record.get("cluster")
            if not isinstance(k, (int, np.integer)) or not 0 <= k < self.k:
                raise ValueError(
                    f"regret: outcome record {dict(outcome.proposal.record)!r} has no valid "
                    "'cluster'; pass back proposals made by this sampler since reset()"
                )
            collided = not outcome.collision_free
            error = (NO_CONTACT_ERROR if self.hear_quality and outcome.holds is False
                     else outcome.error)
            average = (self.regret[k] * self.trials[k] + error) / (self.trials[k] + 1)
            self.regret[k] = (1.0 + self.gamma * collided) * average
            self.trials[k] += 1
            self.pending[k] = max(self.pending[k] - 1, 0)
