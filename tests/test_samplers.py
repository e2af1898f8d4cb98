"""Sampler contract, pose helpers, built-in samplers and the conformance kit itself."""

from __future__ import annotations

import random
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

import isf
import isf.planning.planner
import isf.samplers.base
from isf.exceptions import ConfigError
from isf.object.surface import ObjectSurface
from isf.samplers import (
    NO_CONTACT_ERROR,
    Outcome,
    Proposal,
    RegretSampler,
    Sampler,
    UniformSampler,
    available_samplers,
    get_sampler,
    grasp_centre,
    place_gripper,
    random_rotation,
)
from isf.testing import canonical_gripper, canonical_object, check_sampler

# The canonical gripper's palm sits at (0.01, 0, 0.02) with rpy (0.3, 0, pi/2) and its
# pads are centred 0.05 m along the palm z axis, so the grasp centre in the gripper frame is:
GRASP_CENTRE = np.array([0.01 + 0.05 * np.sin(0.3), 0.0, 0.02 + 0.05 * np.cos(0.3)])


@pytest.fixture(scope="module")
def gripper():
    return canonical_gripper()


@pytest.fixture(scope="module")
def box():
    return canonical_object("box")


# ------------------------------------------------------------------ conformance


@pytest.mark.parametrize("name", sorted(available_samplers()))
def test_every_installed_sampler_conforms(name):
    check_sampler(get_sampler(name))


@pytest.mark.parametrize(
    "sampler", [RegretSampler, UniformSampler, RegretSampler(n_clusters=3, gamma=0.5),
                RegretSampler(hear_quality=True)], ids=repr
)
@pytest.mark.parametrize("kind", ["box", "sphere"])
def test_builtin_samplers_conform(sampler, kind):
    check_sampler(sampler, obj=canonical_object(kind))


class _Broken(UniformSampler):
    """Base of deliberately broken samplers: subclasses override _edit."""

    name = "broken"
    description = "a deliberately broken sampler"

    def propose(self, n, rng):
        return self._edit(super().propose(n, rng), rng)

    def _edit(self, proposals, rng):
        return proposals


def _with_T(p, T):
    return Proposal(T, p.q, p.record)


def _set(T, index, value):
    T = T.copy()
    T[index] = value
    return T


class _Reflection(_Broken):
    def _edit(self, proposals, rng):
        return [_with_T(p, p.T_object_gripper @ np.diag([1.0, 1.0, -1.0, 1.0])) for p in proposals]


class _Scaled(_Broken):
    def _edit(self, proposals, rng):
        return [_with_T(p, p.T_object_gripper @ np.diag([1.1, 1.1, 1.1, 1.0])) for p in proposals]


class _BadLastRow(_Broken):
    def _edit(self, proposals, rng):
        return [_with_T(p, _set(p.T_object_gripper, (3, 0), 0.5)) for p in proposals]


class _NotFinite(_Broken):
    def _edit(self, proposals, rng):
        return [_with_T(p, _set(p.T_object_gripper, (0, 3), np.nan)) for p in proposals]


class _NumpyGlobal(_Broken):
    def _edit(self, proposals, rng):
        np.random.uniform()  # noqa: NPY002 (the global RNG a sampler must not use)
        return proposals


class _PythonGlobal(_Broken):
    def _edit(self, proposals, rng):
        random.random()
        return proposals


class _OwnGenerator(_Broken):
    def _edit(self, proposals, rng):
        return UniformSampler.propose(self, len(proposals), np.random.default_rng())


class _OneShort(_Broken):
    def _edit(self, proposals, rng):
        return proposals[:-1]


class _Tuple(_Broken):
    def _edit(self, proposals, rng):
        return tuple(proposals)


class _BadRecord(_Broken):
    def _edit(self, proposals, rng):
        return [Proposal(p.T_object_gripper, record={"point": {1, 2}}) for p in proposals]


class _JointsOutOfLimits(_Broken):
    def _edit(self, proposals, rng):
        return [Proposal(p.T_object_gripper, q=[0.5], record=p.record) for p in proposals]


@dataclass(eq=False, kw_only=True)
class _Remembers(_Broken):
    """Keeps a counter across plans (reset does not clear it)."""

    count: int = 0

    def _edit(self, proposals, rng):
        self.count += 1
        return [_with_T(p, _set(p.T_object_gripper, (0, 3), 1e-3 * self.count))
                for p in proposals]


class _BadName(UniformSampler):
    name = "Bad Name"


class _VagueHearer(UniformSampler):
    def hears_quality(self):
        return "yes"


@pytest.mark.parametrize(
    ("cls", "message"),
    [
        (_Reflection, "det"),
        (_Scaled, "orthonormal"),
        (_BadLastRow, "last row"),
        (_NotFinite, "not finite"),
        (_NumpyGlobal, "global RNG"),
        (_PythonGlobal, "global RNG"),
        (_OwnGenerator, "same seed"),
        (_OneShort, "exactly n"),
        (_Tuple, "return a list"),
        (_BadRecord, "JSON"),
        (_JointsOutOfLimits, "joint limits"),
        (_Remembers, "reset"),
        (_BadName, "name"),
        (_VagueHearer, "hears_quality"),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else v,
)
def test_check_sampler_catches_broken_samplers(cls, message):
    with pytest.raises(AssertionError, match=message):
        check_sampler(cls)


def test_check_sampler_rejects_non_samplers():
    with pytest.raises(AssertionError, match="not a subclass"):
        check_sampler(dict)


class _Listener(UniformSampler):
    """Keeps every outcome it is shown, in a class attribute (check_sampler copies instances)."""

    heard: ClassVar[list[Outcome]] = []

    def observe(self, outcomes):
        _Listener.heard.extend(outcomes)


def test_check_sampler_shows_each_kind_of_planner_outcome():
    _Listener.heard.clear()
    check_sampler(_Listener)
    kinds = {(o.valid, o.collision_free, o.error == NO_CONTACT_ERROR) for o in _Listener.heard}
    # valid; colliding with its contacts touching; collision-free but not touching
    assert kinds == {(True, True, False), (False, False, False), (False, True, True)}
    assert {o.holds for o in _Listener.heard} == {None}


class _QualityListener(_Listener):
    def hears_quality(self):
        return True


def test_check_sampler_shows_a_hearing_sampler_both_verdicts():
    _Listener.heard.clear()
    check_sampler(_QualityListener)
    assert {o.holds for o in _Listener.heard if o.valid} == {True, False}
    assert {o.holds for o in _Listener.heard if not o.valid} == {None}


# ---------------------------------------------------------------- data classes


def test_proposal_stores_read_only_copies():
    T = np.eye(4)
    record = {"cluster": 1}
    p = Proposal(T, q=[0.01], record=record)
    T[0, 3] = 5.0
    record["cluster"] = 2
    assert p.T_object_gripper[0, 3] == 0.0 and p.record == {"cluster": 1}
    with pytest.raises(ValueError):
        p.T_object_gripper[0, 0] = 2.0
    assert Proposal(np.eye(4)).record == {} and Proposal(np.eye(4)).q is None


@pytest.mark.parametrize(("T", "q"), [(np.eye(3), None), (np.eye(4), np.zeros((1, 1)))])
def test_proposal_rejects_bad_shapes(T, q):
    with pytest.raises(ValueError, match="shape"):
        Proposal(T, q=q)


def test_outcome_rejects_nan_error():
    with pytest.raises(ValueError, match="inf"):
        Outcome(Proposal(np.eye(4)), error=float("nan"), collision_free=True)


@pytest.mark.parametrize(("error", "collision_free", "valid"), [
    (1e-3, True, True), (1e-3, False, False), (NO_CONTACT_ERROR, True, False),
    (NO_CONTACT_ERROR - 1e-9, True, True), (float("inf"), True, False)])
def test_outcome_valid_defaults_to_the_no_contact_convention(error, collision_free, valid):
    outcome = Outcome(Proposal(np.eye(4)), error, np.bool_(collision_free))
    assert outcome.valid is valid


def test_outcome_valid_given_is_kept_and_must_be_collision_free():
    proposal = Proposal(np.eye(4))
    assert Outcome(proposal, 1e-3, True, valid=np.bool_(False)).valid is False
    assert Outcome(proposal, NO_CONTACT_ERROR, True, valid=True).valid is True
    with pytest.raises(ValueError, match="collision_free is False"):
        Outcome(proposal, 1e-3, False, valid=True)


def test_outcome_holds_is_for_valid_grasps_only():
    proposal = Proposal(np.eye(4))
    assert Outcome(proposal, 1e-3, True).holds is None
    assert Outcome(proposal, 1e-3, True, valid=True, holds=np.bool_(False)).holds is False
    with pytest.raises(ValueError, match="not valid"):
        Outcome(proposal, NO_CONTACT_ERROR, True, valid=False, holds=True)


def test_the_no_contact_error_is_one_constant():
    assert isf.planning.planner.NO_CONTACT_ERROR is NO_CONTACT_ERROR


# ------------------------------------------------------------------- helpers


def test_random_rotation_is_haar_distributed():
    R = random_rotation(np.random.default_rng(3), size=20000)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # Haar measure on SO(3): E[R] = 0, E[tr(R)^2] = 1 (the defining representation is
    # irreducible), and the rotation angle has CDF (t - sin t) / pi.
    trace = np.trace(R, axis1=1, axis2=2)
    assert np.abs(R.mean(axis=0)).max() < 0.03
    assert abs(np.mean(trace**2) - 1.0) < 0.05
    angle = np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))
    for t in (0.5, 1.0, 2.0, 3.0):
        assert abs(np.mean(angle <= t) - (t - np.sin(t)) / np.pi) < 0.015
    assert random_rotation(np.random.default_rng(0)).shape == (3, 3)


def test_grasp_centre_matches_the_urdf(gripper):
    np.testing.assert_allclose(grasp_centre(gripper), GRASP_CENTRE, atol=1e-12)


def test_place_gripper_puts_the_grasp_centre_at_the_point(gripper):
    rng = np.random.default_rng(0)
    R = random_rotation(rng, size=4)
    centres = rng.normal(size=(4, 3))
    T = place_gripper(gripper, centres, R)
    assert T.shape == (4, 4, 4)
    np.testing.assert_allclose(T[:, :3, :3], R)
    np.testing.assert_allclose(np.einsum("nij,j->ni", T[:, :3, :3], GRASP_CENTRE) + T[:, :3, 3],
                               centres, atol=1e-12)
    np.testing.assert_array_equal(T[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (4, 1)))
    single = place_gripper(gripper, centres[1], R[1])
    assert single.shape == (4, 4)
    np.testing.assert_allclose(single, T[1])


# -------------------------------------------------------------------- uniform


def test_uniform_draws_surface_points_uniformly(gripper):
    obj = ObjectSurface(points=np.random.default_rng(0).normal(size=(10, 3)),
                        normals=np.tile([0.0, 0.0, 1.0], (10, 1)), spacing=0.1)
    sampler = UniformSampler()
    rng = np.random.default_rng(1)
    sampler.reset(obj, gripper, rng)
    proposals = sampler.propose(5000, rng)
    index = np.array([p.record["point"] for p in proposals])
    counts = np.bincount(index, minlength=10)
    assert np.all(np.abs(counts - 500) < 80)  # binomial sd ~ 21
    for p, k in zip(proposals[:20], index[:20]):
        T = p.T_object_gripper
        np.testing.assert_allclose(T[:3, :3] @ GRASP_CENTRE + T[:3, 3], obj.points[k], atol=1e-12)


def test_propose_before_reset_is_an_error():
    for sampler in (UniformSampler(), RegretSampler()):
        with pytest.raises(RuntimeError, match="reset"):
            sampler.propose(1, np.random.default_rng(0))


# --------------------------------------------------------------------- regret


def _blobs(n_per_blob=50, spread=0.002):
    """Six tight blobs at +-5 cm on each axis: k-means must find their means."""
    rng = np.random.default_rng(7)
    means = np.vstack([np.eye(3), -np.eye(3)]) * 0.05
    points = (means[:, None, :] + spread * rng.standard_normal((6, n_per_blob, 3))).reshape(-1, 3)
    obj = ObjectSurface(points=points, normals=np.tile([0.0, 0.0, 1.0], (len(points), 1)),
                        spacing=spread)
    return obj, points.reshape(6, n_per_blob, 3).mean(axis=1)


def test_kmeans_finds_separated_blobs(gripper):
    obj, blob_means = _blobs()
    sampler = RegretSampler()
    sampler.reset(obj, gripper, np.random.default_rng(0))
    # match each blob to its nearest centre: a one-to-one match, at the blob mean
    match = np.argmin(np.linalg.norm(blob_means[:, None] - sampler.centres[None], axis=2), axis=1)
    assert sorted(match) == list(range(6))
    np.testing.assert_allclose(sampler.centres[match], blob_means, atol=1e-12)
    np.testing.assert_array_equal(sampler.labels.reshape(6, -1), np.repeat(match[:, None], 50, 1))


def test_kmeans_result_is_a_lloyd_fixed_point(gripper, box):
    sampler = RegretSampler(kmeans_iterations=100)
    sampler.reset(box, gripper, np.random.default_rng(0))
    d = np.linalg.norm(box.points[:, None, :] - sampler.centres[None], axis=2)
    own = d[np.arange(len(box.points)), sampler.labels]
    assert np.all(own <= d.min(axis=1) + 1e-15), "a point is closer to another centre"
    for k in range(6):
        np.testing.assert_allclose(sampler.centres[k], box.points[sampler.labels == k].mean(0),
                                   atol=1e-12)


def test_regret_bookkeeping_follows_algorithm_3(gripper):
    obj, _ = _blobs()
    sampler = RegretSampler(n_clusters=3, gamma=0.5, com_share=0)
    rng = np.random.default_rng(0)
    sampler.reset(obj, gripper, rng)
    # (error, collision_free) fed back, and the cluster Alg. 3 must pick before each:
    #   regret [0, 0, 0]         -> 0; 0.2 collides:   0.2 * 1.5           = 0.3
    #   regret [.3, 0, 0]        -> 1; 0.1 free:       0.1
    #   regret [.3, .1, 0]       -> 2; 0.4 free:       0.4
    #   regret [.3, .1, .4]      -> 1; 0.3 collides:   (0.1 + 0.3)/2 * 1.5 = 0.3
    #   regret [.3, .3, .4] tie  -> 0; 0.0 free:       (0.3 + 0.0)/2       = 0.15
    steps = [(0, 0.0, 0.2, False), (1, 0.0, 0.1, True), (2, 0.0, 0.4, True),
             (1, 0.1, 0.3, False), (0, 0.3, 0.0, True)]
    for cluster, regret_before, error, free in steps:
        (p,) = sampler.propose(1, rng)
        assert p.record["cluster"] == cluster
        assert p.record["regret"] == pytest.approx(regret_before)
        T = p.T_object_gripper
        np.testing.assert_allclose(T[:3, :3] @ GRASP_CENTRE + T[:3, 3], sampler.centres[cluster],
                                   atol=1e-12)
        sampler.observe([Outcome(p, error=error, collision_free=free)])
    np.testing.assert_allclose(sampler.regret, [0.15, 0.3, 0.4])
    np.testing.assert_array_equal(sampler.trials, [2, 2, 1])
    assert sampler.best_cluster() == 0


def test_regret_hearing_the_quality_counts_a_grasp_not_expected_to_hold_as_no_contact(gripper):
    obj, _ = _blobs()
    for hear, expected in ((False, [0.002, 0.004, 0.003]),
                           (True, [0.002, NO_CONTACT_ERROR, 0.003])):
        sampler = RegretSampler(n_clusters=3, com_share=0, hear_quality=hear)
        assert sampler.hears_quality() is hear
        rng = np.random.default_rng(0)
        sampler.reset(obj, gripper, rng)
        # holds: True, False, None (what a plan ranked by fit reports)
        for error, holds in ((0.002, True), (0.004, False), (0.003, None)):
            (p,) = sampler.propose(1, rng)
            sampler.observe([Outcome(p, error, True, valid=True, holds=holds)])
        np.testing.assert_allclose(sampler.regret, expected)


def test_regret_batch_proposes_at_one_cluster_with_distinct_rotations(gripper, box):
    sampler = RegretSampler(com_share=0)
    rng = np.random.default_rng(0)
    sampler.reset(box, gripper, rng)
    proposals = sampler.propose(4, rng)
    assert {p.record["cluster"] for p in proposals} == {0}
    rotations = np.array([p.T_object_gripper[:3, :3] for p in proposals])
    assert len({r.tobytes() for r in rotations}) == 4
    sampler.observe([Outcome(p, error=0.01, collision_free=True) for p in proposals])
    assert sampler.trials[0] == 4 and sampler.regret[0] == pytest.approx(0.01)
    sampler.reset(box, gripper, rng)
    assert not sampler.trials.any() and not sampler.regret.any()


def test_regret_rejects_foreign_outcomes(gripper, box):
    sampler = RegretSampler()
    sampler.reset(box, gripper, np.random.default_rng(0))
    with pytest.raises(ValueError, match="cluster"):
        sampler.observe([Outcome(Proposal(np.eye(4)), error=0.1, collision_free=True)])


def _dumbbell():
    """Two disjoint boxes as one closed mesh: 4 cm cube at the origin and a 1 x 1 x 8 cm bar
    centred at x = 10 cm. Solid centre of mass x = 0.10 * 8 / 72 m; the surface's area-weighted
    centroid lies at x = 0.10 * 34 / 130 m."""
    import trimesh

    bar = trimesh.creation.box(extents=(0.01, 0.01, 0.08))
    bar.apply_translation((0.10, 0.0, 0.0))
    mesh = trimesh.util.concatenate([trimesh.creation.box(extents=(0.04, 0.04, 0.04)), bar])
    return isf.load_object(mesh, voxel_size=0.004)


def test_regret_starts_a_share_at_the_solid_centre_of_mass(gripper):
    obj = _dumbbell()
    centre = np.array([0.10 * 8 / 72, 0.0, 0.0])
    for share, expected in ((0.5, [1, 3, 5, 7, 9, 11]), (1 / 3, [2, 5, 8, 11]), (0.0, [])):
        sampler = RegretSampler(com_share=share)
        rng = np.random.default_rng(0)
        sampler.reset(obj, gripper, rng)
        proposals = sampler.propose(4, rng) + [p for _ in range(8)
                                               for p in sampler.propose(1, rng)]
        at_centre = [i for i, p in enumerate(proposals) if p.record.get("start") == "centre_of_mass"]
        assert at_centre == expected
        for i in at_centre:
            T = proposals[i].T_object_gripper
            np.testing.assert_allclose(T[:3, :3] @ GRASP_CENTRE + T[:3, 3], centre, atol=1e-9)
        approach = [proposals[i].T_object_gripper[:3, 2] for i in at_centre]
        assert len({a.round(6).tobytes() for a in approach}) == len(at_centre)  # random turns
        # outcomes of centre-of-mass starts leave the clusters' regret alone
        trials = sampler.trials.copy()
        sampler.observe([Outcome(proposals[i], error=0.003, collision_free=True)
                         for i in at_centre])
        np.testing.assert_array_equal(sampler.trials, trials)


def test_regret_makes_no_centre_of_mass_start_on_a_scene(gripper):
    obj = _dumbbell()
    seen = ObjectSurface(points=obj.points, normals=obj.normals, spacing=obj.spacing,
                         viewpoints=np.array([[0.0, 0.0, 0.5]]))
    sampler = RegretSampler(com_share=0.5)
    rng = np.random.default_rng(0)
    sampler.reset(seen, gripper, rng)
    assert sampler.centre_of_mass is None
    assert all("cluster" in p.record for p in sampler.propose(6, rng))


@pytest.mark.parametrize(
    "params",
    [{"n_clusters": 0}, {"n_clusters": 2.5}, {"n_clusters": True}, {"gamma": -0.1},
     {"gamma": float("nan")}, {"gamma": "0.2"}, {"kmeans_iterations": 0}, {"com_share": 1.0},
     {"com_share": -0.1}, {"com_share": "0.5"}, {"com_share": True}, {"hear_quality": "yes"},
     {"hear_quality": 2}],
)
def test_regret_validates_parameters(params):
    key = next(iter(params))
    with pytest.raises(ConfigError, match=key):
        RegretSampler(**params)


@pytest.mark.parametrize(("value", "flag"), [(True, True), ("false", False), ("True", True),
                                             (1, True), (np.bool_(False), False)])
def test_regret_reads_hear_quality_as_a_flag(value, flag):
    assert RegretSampler(hear_quality=value).hear_quality is flag  # e.g. --sampler-param text


@pytest.mark.parametrize(("value", "low", "kept"), [(3, 1, 3), (np.int64(0), 0, 0)])
def test_integer_parameter_keeps_whole_numbers_in_range(value, low, kept):
    result = isf.samplers.integer_parameter(value, "mine", "spins", low)
    assert result == kept and type(result) is int


@pytest.mark.parametrize("value", [0, 2.0, True, "3", None])
def test_integer_parameter_refuses_in_one_line(value):
    with pytest.raises(ConfigError) as caught:
        isf.samplers.integer_parameter(value, "mine", "spins", 1)
    assert str(caught.value) == f"mine: spins must be an integer >= 1, got {value!r}"


@pytest.mark.parametrize(("value", "below"), [(0, None), (np.float32(2.5), None), (0.999, 1.0)])
def test_number_parameter_keeps_numbers_in_range(value, below):
    result = isf.samplers.number_parameter(value, "mine", "weight", below=below)
    assert result == pytest.approx(float(value)) and type(result) is float


@pytest.mark.parametrize(("value", "below", "allowed"), [
    (-0.1, None, "a finite number >= 0"), (float("inf"), None, "a finite number >= 0"),
    (float("nan"), None, "a finite number >= 0"), (False, None, "a finite number >= 0"),
    ("1", None, "a finite number >= 0"), (1.0, 1.0, "a number in [0, 1)"),
])
def test_number_parameter_refuses_in_one_line(value, below, allowed):
    with pytest.raises(ConfigError) as caught:
        isf.samplers.number_parameter(value, "mine", "weight", below=below)
    assert str(caught.value) == f"mine: weight must be {allowed}, got {value!r}"


def test_regret_needs_enough_points(gripper):
    obj = ObjectSurface(points=np.eye(3), normals=np.eye(3), spacing=1.0)
    with pytest.raises(ConfigError, match="n_clusters=6 exceeds the object's 3 points"):
        RegretSampler().reset(obj, gripper, np.random.default_rng(0))


def test_samplers_are_keyword_only():
    with pytest.raises(TypeError):
        RegretSampler(3)  # type: ignore[misc]
    assert issubclass(RegretSampler, Sampler)


# ------------------------------------------------------- what the planner reports


class _Numbering(UniformSampler):
    """The uniform sampler, each proposal numbered in ``record["start"]`` and each outcome
    kept under that number."""

    def reset(self, obj, gripper, rng):
        super().reset(obj, gripper, rng)
        self.made, self.outcomes = 0, {}

    def propose(self, n, rng):
        proposals = []
        for proposal in super().propose(n, rng):
            proposals.append(Proposal(proposal.T_object_gripper,
                                      record={**proposal.record, "start": self.made}))
            self.made += 1
        return proposals

    def observe(self, outcomes):
        self.outcomes.update((o.proposal.record["start"], o) for o in outcomes)


def _outcomes_against_grasps(gripper, obj, samples):
    """Plan with :class:`_Numbering`; each grasp with the outcome the sampler was shown."""
    sampler = _Numbering()
    result = isf.plan(gripper, obj, samples=samples, sampler=sampler, seed=0)
    assert len(sampler.outcomes) == len(result.grasps) == samples
    return [(g, sampler.outcomes[g.sampler_record["start"]]) for g in result.grasps]


@pytest.fixture
def no_inference(monkeypatch):
    """Outcomes built without ``valid`` all come out invalid: what the planner's outcomes
    say of validity is then its own statement (its error for a fit that does not touch is
    unchanged: the planner holds the constant's value)."""
    monkeypatch.setattr(isf.samplers.base, "NO_CONTACT_ERROR", 0.0)


def _assert_outcomes_are_the_grasps_verdicts(pairs):
    for grasp, outcome in pairs:
        assert outcome.valid is grasp.valid
        assert outcome.collision_free is grasp.collision_free


def test_the_planners_outcomes_carry_each_grasps_validity(no_inference):
    pairs = _outcomes_against_grasps("three-finger", isf.open_object("asset:mug"), 12)
    _assert_outcomes_are_the_grasps_verdicts(pairs)
    grasps = [g for g, _ in pairs]
    assert any(g.valid for g in grasps)
    assert any(not g.collision_free for g in grasps)  # some collide ...
    assert any(g.collision_free and not g.in_contact for g in grasps)  # ... some do not touch


def test_the_three_argument_outcome_infers_the_planners_verdict():
    pairs = _outcomes_against_grasps("three-finger", isf.open_object("asset:mug"), 12)
    for grasp, outcome in pairs:
        assert Outcome(outcome.proposal, outcome.error, outcome.collision_free).valid is grasp.valid


def test_on_a_scene_a_grasp_across_two_pieces_is_an_invalid_outcome(no_inference):
    from _depth_camera import box_on_table, look_at, render_depth, table_mesh

    from isf.scene import SceneView, load_scene

    # two boxes side by side, touching along x = 0, seen from either side
    boxes = [box_on_table((0.03, 0.05, 0.08), (-0.016, 0.0)),
             box_on_table((0.03, 0.05, 0.06), (0.016, 0.0))]
    views = []
    for k, eye in enumerate([(-0.4, 0.1, 0.3), (0.4, -0.1, 0.3)]):
        T_scene_camera = look_at(eye, (0.0, 0.0, 0.04))
        depth, intrinsics = render_depth([table_mesh(), *boxes], T_scene_camera, noise=0.001,
                                         seed=k)
        views.append(SceneView(depth, intrinsics=intrinsics, T_scene_camera=T_scene_camera))
    pairs = _outcomes_against_grasps("flat-parallel", load_scene(views, table="auto"), 12)
    _assert_outcomes_are_the_grasps_verdicts(pairs)
    grasps = [g for g, _ in pairs]
    assert any(g.valid for g in grasps)
    assert any(g.collision_free and g.in_contact and g.pieces == 2 for g in grasps)


class _NumberingHearer(_Numbering):
    """:class:`_Numbering` asking for the quality ranking's verdict; it proposes the same."""

    def hears_quality(self):
        return True


def test_a_sampler_that_hears_the_quality_gets_the_rankings_verdict_on_the_same_plan():
    from isf.quality import expected_to_hold

    obj = isf.open_object("asset:mug")
    plans, heard = [], []
    for sampler in (_Numbering(), _NumberingHearer()):
        plans.append(isf.plan("three-finger", obj, samples=12, sampler=sampler, seed=0))
        heard.append(sampler.outcomes)
    plain, hearing = plans
    # computing the quality as outcomes arrive changes nothing in the plan
    assert [g.sample_index for g in plain.grasps] == [g.sample_index for g in hearing.grasps]
    for a, b in zip(plain.grasps, hearing.grasps):
        assert (a.quality is None) is (b.quality is None)
        if a.quality is not None:
            assert a.quality.to_dict() == b.quality.to_dict()
            assert a.closing_obstructed_by == b.closing_obstructed_by
    # what the hearing sampler heard is the verdict of the grasp's final record
    by_start = {g.sampler_record["start"]: g for g in hearing.grasps}
    assert any(g.valid for g in hearing.grasps)
    for start, outcome in heard[1].items():
        grasp = by_start[start]
        expected = (expected_to_hold(grasp.quality,
                                     closing_obstructed=bool(grasp.closing_obstructed_by))
                    if grasp.valid else None)
        assert outcome.holds is expected
    assert all(o.holds is None for o in heard[0].values())
    # ranked by fit there is no verdict to hear
    sampler = _NumberingHearer()
    isf.plan("three-finger", obj, samples=6, sampler=sampler, seed=0, rank="fit")
    assert all(o.holds is None for o in sampler.outcomes.values())
