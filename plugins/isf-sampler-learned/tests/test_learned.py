"""Tests of the ``learned`` sampler plugin: conformance, features, model, training."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import isf
from isf.samplers import NO_CONTACT_ERROR, Outcome, available_samplers, get_sampler
from isf.samplers.regret import RegretSampler
from isf.testing import canonical_gripper, canonical_object, check_sampler
from isf_sampler_learned import (
    FEATURE_VERSION,
    LearnedSampler,
    ModelFileError,
    NoModelWarning,
    gripper_sha256,
    load_model,
)
from isf_sampler_learned.bundled import bundled_models
from isf_sampler_learned.features import (
    FEATURE_NAMES,
    ObjectDescriptors,
    candidate_features,
    gripper_axes,
)
from isf_sampler_learned.model import MODEL_FORMAT, fit_model
from isf_sampler_learned.training import (
    Examples,
    collect_examples,
    object_ranking,
    plan_starts,
)

BUNDLED = ("paper-parallel", "flat-parallel", "three-finger")


def synthetic_model(gripper, path, feature=0):
    """A model for ``gripper`` fitted to labels 'valid when feature ``feature`` > 0.5'."""
    rng = np.random.default_rng(7)
    x = rng.uniform(0.0, 1.0, size=(400, len(FEATURE_NAMES)))
    valid = x[:, feature] > 0.5
    error = np.where(valid, 1e-3 * (1.0 + x[:, 1]), np.inf)
    model = fit_model(x, valid, error, gripper_sha256=gripper_sha256(gripper),
                      gripper_name=gripper.name)
    return model.save(path)


def test_entry_point_reaches_the_sampler():
    assert available_samplers()["learned"].distribution == "isf-sampler-learned"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoModelWarning)
        assert isinstance(get_sampler("learned"), LearnedSampler)


def test_conformance(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NoModelWarning)
        check_sampler(LearnedSampler)
        check_sampler(LearnedSampler, gripper=canonical_gripper(approach=None))
    check_sampler(LearnedSampler(model="none", spins=4, pool=8),
                  obj=canonical_object("sphere"))
    path = synthetic_model(canonical_gripper(), tmp_path / "canonical.npz")
    check_sampler(LearnedSampler(model=str(path)))


@pytest.mark.parametrize("param, message", [
    ("spins=0", "spins must be an integer >= 1"),
    ("model_arms=-1", "model_arms must be an integer >= 0"),
    ("gamma=-1", "gamma must be a finite number >= 0"),
    ("exploration=-1", "exploration must be a finite number >= 0"),
    ("model=3", "model must be"),
    ("clutter_model_arms=2", "clutter_model_arms must be true or false"),
])
def test_bad_parameters_are_one_line_config_errors(param, message):
    key, value = param.split("=")
    with pytest.raises(isf.ConfigError, match=message) as err:
        LearnedSampler(**{key: int(value)})
    assert "\n" not in str(err.value)


def box_face_start():
    """The canonical gripper facing the canonical box's top face (normal +z) at the sample
    point nearest its centre, closing along the box's 6 cm x axis: centre (3,), R (3, 3)."""
    gripper, obj = canonical_gripper(), canonical_object("box")
    axes = gripper_axes(gripper)
    top = np.flatnonzero(obj.normals[:, 2] > 0.99)
    centre = obj.points[top[np.argmin(np.linalg.norm(obj.points[top, :2], axis=1))]]
    source = np.column_stack([axes.approach, axes.closing, np.cross(axes.approach, axes.closing)])
    target = np.column_stack([[0, 0, -1.0], [1.0, 0, 0], np.cross([0, 0, -1.0], [1.0, 0, 0])])
    return gripper, obj, axes, centre, target @ source.T


def test_gripper_axes_of_the_canonical_gripper():
    gripper, _, axes, _, _ = box_face_start()
    palm = gripper.link_poses(gripper.q_initial)["palm"][:3, :3]
    assert axes.opening == pytest.approx(0.04, abs=1e-9)  # pads 2 x 0.02 m from the palm
    assert abs(axes.closing @ palm[:, 1]) == pytest.approx(1.0, abs=1e-9)  # the palm's y
    np.testing.assert_allclose(axes.approach, palm[:, 2], atol=1e-12)  # declared (0, 0, 1)


def test_features_of_a_start_on_a_box_face_match_the_box():
    _, obj, axes, centre, R = box_face_start()
    f = dict(zip(FEATURE_NAMES, candidate_features(ObjectDescriptors.build(obj, axes), axes,
                                                   centre[None], R[None])[0]))
    assert f["approach_cos"] == pytest.approx(1.0)
    assert f["closing_normal"] == pytest.approx(0.0, abs=1e-12)
    assert f["closing_extent"] == pytest.approx(0.06 / 0.04, abs=1e-9)  # end faces at x = +-3 cm
    assert f["approach_depth"] == pytest.approx(0.03 / 0.04, abs=1e-9)  # bottom face 3 cm down
    assert f["closing_offset"] == pytest.approx(abs(centre[0]) / 0.04, abs=1e-9)
    assert f["surface_distance"] == 0.0
    assert f["surface_variation"] == pytest.approx(0.0, abs=1e-12)  # flat within 2 cm
    # principal axes of 400 random samples tilt a little off the box's: a few mm more extent
    np.testing.assert_allclose([f["object_major"], f["object_middle"], f["object_minor"]],
                               np.array([0.06, 0.04, 0.03]) / 0.04, atol=0.1)


def test_a_second_object_apart_leaves_the_features_of_a_start_unchanged():
    """On a surface of two objects (a scene) the extents are those of the object under the
    start: the box face start gives the features of the box alone, not of the pair, though the
    closing line through it runs on through the second object."""
    _, box, axes, centre, R = box_face_start()
    sphere = canonical_object("sphere")
    beside = sphere.points + [0.15, 0.0, 0.0]  # on the closing line (x), 9 cm beyond the box
    pair = isf.ObjectSurface(points=np.vstack([box.points, beside]),
                             normals=np.vstack([box.normals, sphere.normals]),
                             spacing=max(box.spacing, sphere.spacing))
    alone = candidate_features(ObjectDescriptors.build(box, axes), axes, centre[None], R[None])
    within = candidate_features(ObjectDescriptors.build(pair, axes), axes, centre[None], R[None])
    np.testing.assert_allclose(within, alone, atol=1e-12)
    extents = ObjectDescriptors.build(pair, axes).extents
    assert len(extents) == 2  # one piece per object
    # each piece spans at most its 6 cm; the pair together spans about 21 cm
    assert extents[:, 0].max() * axes.opening < 0.065 < 0.2 < np.ptp(pair.points[:, 0])


def two_boxes(gap: float, stray: int = 0) -> isf.ObjectSurface:
    """The canonical box and a copy moved ``gap`` metres along x beyond it, plus ``stray``
    isolated points (a sensor's stray returns) scattered far from both."""
    box = canonical_object("box")
    width = np.ptp(box.points[:, 0])
    rng = np.random.default_rng(5)
    lonely = rng.uniform(-1.0, 1.0, size=(stray, 3)) * 0.05 + [0.0, 0.0, 0.3]
    lonely[:, 0] += np.arange(stray) * 10 * box.spacing  # no two within a piece's gap
    up = np.tile([0.0, 0.0, 1.0], (stray, 1))
    return isf.ObjectSurface(points=np.vstack([box.points, box.points + [width + gap, 0, 0],
                                               lonely]),
                             normals=np.vstack([box.normals, box.normals, up]),
                             spacing=box.spacing)


def test_major_pieces_count_the_objects_not_the_stray_points():
    axes = gripper_axes(canonical_gripper())
    box = canonical_object("box")
    assert ObjectDescriptors.build(box, axes).major_pieces == 1
    apart = ObjectDescriptors.build(two_boxes(gap=0.02, stray=12), axes)
    assert len(apart.piece_points) == 2 + 12 and apart.major_pieces == 2
    # touching boxes (a gap below PIECE_GAP spacings) are one piece, as on a scene
    assert ObjectDescriptors.build(two_boxes(gap=box.spacing), axes).major_pieces == 1


def test_model_arms_are_placed_on_an_object_and_left_out_on_clutter(tmp_path):
    gripper = canonical_gripper()
    path = synthetic_model(gripper, tmp_path / "m.npz", feature=2)
    # "true" as isf plan --sampler-param clutter_model_arms=true passes it
    for surface, clutter, added in ((canonical_object("box"), False, 3),
                                    (two_boxes(gap=0.02), False, 0),
                                    (two_boxes(gap=0.02), "true", 3)):
        sampler = LearnedSampler(model=str(path), model_arms=3, clutter_model_arms=clutter)
        sampler.reset(surface, gripper, np.random.default_rng(6))
        assert sampler.bandit.k == sampler.k_clusters + added
        assert sampler.prior_valid.shape == (sampler.bandit.k,)


def test_features_do_not_depend_on_the_object_frame():
    _, obj, axes, centre, R = box_face_start()
    moved = isf.ObjectSurface(points=obj.points @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]).T
                              + [0.3, -0.2, 0.1], normals=obj.normals @ np.array(
                                  [[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]).T, spacing=obj.spacing)
    turn = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    before = candidate_features(ObjectDescriptors.build(obj, axes), axes, centre[None], R[None])
    after = candidate_features(ObjectDescriptors.build(moved, axes), axes,
                               (turn @ centre + [0.3, -0.2, 0.1])[None], (turn @ R)[None])
    np.testing.assert_allclose(after, before, atol=1e-9)


def test_batched_features_match_a_point_by_point_computation():
    """Tubes, shared lines (the same centre, the opposite direction) and the neighbourhood
    descriptors against a plain loop over the object's points."""
    gripper, obj = isf.load_gripper("paper-parallel"), isf.open_object("asset:duck")
    axes = gripper_axes(gripper)
    rng = np.random.default_rng(2)
    centres = obj.points[rng.choice(obj.n_points, 6)] + rng.normal(scale=2e-3, size=(6, 3))
    R = isf.samplers.random_rotation(rng, size=6)
    flip = np.diag([-1.0, -1.0, 1.0])  # a half turn about z: another closing sign
    centres, R = np.vstack([centres, centres]), np.concatenate([R, R @ flip])
    features = candidate_features(ObjectDescriptors.build(obj, axes), axes, centres, R)
    w, points = axes.opening, obj.points
    for f, c, Rm in zip(features, centres, R):
        ranges = []
        for d in (Rm @ axes.closing, Rm @ axes.approach):
            along = [(p - c) @ d for p in points
                     if np.linalg.norm(p - c - ((p - c) @ d) * d) <= 0.25 * w]
            ranges.append((min(along), max(along)) if along else (0.0, 0.0))
        (low, high), (_, depth) = ranges
        assert f[2] == pytest.approx((high - low) / w, abs=1e-9)
        assert f[3] == pytest.approx(abs(0.5 * (high + low)) / w, abs=1e-9)
        assert f[4] == pytest.approx(max(depth, 0.0) / w, abs=1e-9)
        nearest = np.argmin(np.linalg.norm(points - c, axis=1))
        near = np.linalg.norm(points - points[nearest], axis=1) <= 0.5 * w
        eigen = np.linalg.eigvalsh(np.cov(points[near].T))
        assert f[5] == pytest.approx(eigen[0] / eigen.sum(), abs=1e-9)
        assert f[6] == pytest.approx(1 - np.linalg.norm(obj.normals[near].mean(axis=0)),
                                     abs=1e-9)


def test_validity_head_matches_scikit_learn_logistic_regression():
    sklearn = pytest.importorskip("sklearn.linear_model")
    rng = np.random.default_rng(3)
    x = rng.normal(size=(300, len(FEATURE_NAMES)))
    valid = rng.uniform(size=300) < 1 / (1 + np.exp(-(x[:, 0] - x[:, 2] ** 2)))
    model = fit_model(x, valid, np.full(300, 1e-3), gripper_sha256="0" * 64, gripper_name="g",
                      l2=2.0)
    B = model.basis(x)[:, 1:]
    reference = sklearn.LogisticRegression(C=1 / 2.0, tol=1e-12, max_iter=10000).fit(B, valid)
    np.testing.assert_allclose(model.p_valid(x), reference.predict_proba(B)[:, 1], atol=1e-5)


def test_model_file_round_trip_and_refusals(tmp_path):
    gripper = canonical_gripper()
    path = synthetic_model(gripper, tmp_path / "m")
    assert path.suffix == ".npz"
    model = load_model(path, gripper_sha256=gripper_sha256(gripper))
    x = np.random.default_rng(1).uniform(size=(50, len(FEATURE_NAMES)))
    assert ((model.p_valid(x) > 0.5) == (x[:, 0] > 0.5)).mean() > 0.9

    other = canonical_gripper(approach=None)
    with pytest.raises(ModelFileError, match="trained for gripper 'isf_test_gripper'") as err:
        load_model(path, gripper_sha256=gripper_sha256(other))
    assert "\n" not in str(err.value)

    with np.load(path, allow_pickle=False) as data:
        fields = dict(data)
    np.savez(tmp_path / "old.npz", **{**fields, "feature_version": np.array("features/0")})
    with pytest.raises(ModelFileError, match=f"this plugin computes '{FEATURE_VERSION}'"):
        load_model(tmp_path / "old.npz")
    np.savez(tmp_path / "pickled.npz", format=np.array(MODEL_FORMAT),
             feature_version=np.array([{"not": "plain"}], dtype=object))
    with pytest.raises(ModelFileError, match="cannot read sampler model"):
        load_model(tmp_path / "pickled.npz")
    (tmp_path / "text.npz").write_text("not a model")
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "text.npz")


def test_a_model_for_another_gripper_fails_the_plan_with_one_line(tmp_path):
    path = synthetic_model(canonical_gripper(), tmp_path / "canonical.npz")
    with pytest.raises(ModelFileError, match="not this one"):
        isf.plan("paper-parallel", isf.open_object("shape:box"), samples=1,
                 sampler=LearnedSampler(model=str(path)))


def test_the_first_proposal_follows_the_model(tmp_path):
    gripper, obj = canonical_gripper(), canonical_object("box")
    # valid when the approach axis faces the surface: every facing start scores high, so use
    # the closing extent (feature 2) to rank them instead
    path = synthetic_model(gripper, tmp_path / "m.npz", feature=2)
    # a prior worth 10^6 outcomes: the Thompson draw is the prior itself
    sampler = LearnedSampler(model=str(path), exploration=0.0, model_arms=2,
                             prior_strength=1e6)
    rng = np.random.default_rng(0)
    sampler.reset(obj, gripper, rng)
    assert sampler.bandit.k == sampler.k_clusters + 2
    # the synthetic model is nearly certain everywhere: give the arms distinct priors
    sampler.prior_valid = rng.permutation(np.linspace(0.1, 0.9, sampler.bandit.k))
    first = sampler.propose(1, rng)[0]
    k, i = first.record["cluster"], first.record["spin"]
    assert k == int(np.argmax(sampler.prior_valid))
    assert sampler.score[k, i] == sampler.score[k].max()
    assert first.record["p_valid"] == sampler.p_valid[k, i]
    with pytest.raises(ValueError, match="learned: outcome record"):
        sampler.observe([Outcome(isf.samplers.Proposal(np.eye(4)), 1e-3, True)])


def test_outcomes_take_over_from_the_model(tmp_path):
    gripper, obj = canonical_gripper(), canonical_object("box")
    path = synthetic_model(gripper, tmp_path / "m.npz", feature=2)
    sampler = LearnedSampler(model=str(path), arm_error_weight=0.0)
    rng = np.random.default_rng(1)
    sampler.reset(obj, gripper, rng)
    # the arm the model likes least is the only one whose grasps are valid
    good = int(np.argmin(sampler.prior_valid))
    chosen = []
    for _ in range(60):
        (proposal,) = sampler.propose(1, rng)
        k = proposal.record["cluster"]
        chosen.append(k)
        valid = k == good
        sampler.observe([Outcome(proposal, 1e-3 if valid else NO_CONTACT_ERROR,
                                 collision_free=valid, valid=valid)])
    assert sampler.hits[good] == chosen.count(good)
    assert sampler.hits.sum() == sampler.hits[good]
    # every draw of the last 20 goes to the good arm (Beta(31+, ~1) against Beta(~1, 3+))
    assert chosen[-20:].count(good) >= 18
    # the regret table is the regret sampler's: mean error, collisions penalised by gamma
    bad = [k for k in set(chosen) if k != good]
    np.testing.assert_allclose(sampler.bandit.regret[good], 1e-3)
    assert all(sampler.bandit.regret[k] > NO_CONTACT_ERROR for k in bad)


def test_a_valid_spin_is_preferred_at_its_arm(tmp_path):
    gripper, obj = canonical_gripper(), canonical_object("box")
    path = synthetic_model(gripper, tmp_path / "m.npz", feature=2)
    sampler = LearnedSampler(model=str(path), exploration=0.0, spin_evidence=100.0)
    rng = np.random.default_rng(2)
    sampler.reset(obj, gripper, rng)
    (proposal,) = sampler.propose(1, rng)
    k, i = proposal.record["cluster"], proposal.record["spin"]
    worst = int(np.argmin(sampler.score[k]))
    fake = isf.samplers.Proposal(proposal.T_object_gripper, record={"cluster": k, "spin": worst})
    sampler.observe([Outcome(proposal, NO_CONTACT_ERROR, collision_free=False, valid=False),
                     Outcome(fake, 1e-3, collision_free=True, valid=True)])
    np.testing.assert_array_equal(np.flatnonzero(sampler.evidence[k]), sorted({i, worst}))
    assert sampler.evidence[k, worst] == 1 and sampler.evidence[k, i] == -1
    # the bonus of 100 logit units outweighs any score difference: the valid spin is next
    noisy = sampler.score[k] + sampler.spin_evidence * sampler.evidence[k]
    assert int(np.argmax(noisy)) == worst


def test_validity_is_the_outcomes_own_flag(tmp_path):
    gripper, obj = canonical_gripper(), canonical_object("box")
    path = synthetic_model(gripper, tmp_path / "m.npz", feature=2)
    sampler = LearnedSampler(model=str(path))
    rng = np.random.default_rng(3)
    sampler.reset(obj, gripper, rng)
    first, second = sampler.propose(2, rng)
    # the flag against the error convention, both ways: the sampler must read the flag
    sampler.observe([Outcome(first, 1e-3, collision_free=True, valid=False),
                     Outcome(second, 2 * NO_CONTACT_ERROR, collision_free=True, valid=True)])
    expected_hits, expected_evidence = np.zeros(sampler.bandit.k), np.zeros((sampler.bandit.k,
                                                                             sampler.spins))
    for proposal, sign in ((first, -1.0), (second, 1.0)):
        expected_evidence[proposal.record["cluster"], proposal.record["spin"]] += sign
    expected_hits[second.record["cluster"]] = 1
    np.testing.assert_array_equal(sampler.hits, expected_hits)
    np.testing.assert_array_equal(sampler.evidence, expected_evidence)
    np.testing.assert_allclose(sampler.valid_error.sum(), 2 * NO_CONTACT_ERROR)


def test_without_a_model_the_arms_are_the_regret_samplers_clusters():
    gripper, obj = canonical_gripper(), canonical_object("box")
    learned, regret = LearnedSampler(model="none"), RegretSampler()
    learned.reset(obj, gripper, np.random.default_rng(4))
    regret.reset(obj, gripper, np.random.default_rng(4))
    np.testing.assert_array_equal(learned.bandit.centres, regret.centres)
    assert learned.bandit.k == learned.k_clusters == regret.k
    # spins evenly spaced about each cluster's inward direction, approach axis facing it
    approach = learned.R[..., :, :] @ gripper_axes(gripper).approach
    inward = regret.inward / np.linalg.norm(regret.inward, axis=1, keepdims=True)
    np.testing.assert_allclose(approach, np.repeat(inward[:, None], learned.spins, axis=1),
                               atol=1e-9)


def test_training_examples_are_labelled_and_deterministic():
    gripper = isf.load_gripper("flat-parallel")
    objects = [isf.open_object("shape:box"), isf.open_object("shape:sphere")]
    one = collect_examples(gripper, objects, samplers=("uniform",), samples=4, seed=5)
    two = collect_examples(gripper, objects, samplers=("uniform",), samples=4, seed=5)
    np.testing.assert_array_equal(one.features, two.features)
    np.testing.assert_array_equal(one.valid, two.valid)
    assert one.features.shape == (8, len(FEATURE_NAMES)) and list(one.group) == [0] * 4 + [1] * 4
    plan = isf.plan(gripper, objects[0], samples=4, sampler="uniform", seed=5)
    assert sorted(one.valid[:4]) == sorted(g.valid for g in plan.grasps)


def test_planned_starts_are_the_samplers_starts_with_their_grasps_outcomes():
    from isf.samplers import grasp_centre

    gripper = isf.load_gripper("flat-parallel")
    obj = isf.open_object("shape:box")
    planned = plan_starts(gripper, obj, "uniform", samples=6, seed=3)
    plan = isf.plan(gripper, obj, samples=6, sampler="uniform", seed=3)
    np.testing.assert_array_equal(planned.valid, [g.valid for g in plan.grasps])
    np.testing.assert_array_equal(planned.error, [g.fit.mean_distance for g in plan.grasps])
    # the uniform sampler puts the grasp centre on a point of the surface the plan matched
    T = planned.T_object_gripper
    centres = T[:, :3, :3] @ grasp_centre(gripper) + T[:, :3, 3]
    gaps = np.linalg.norm(centres[:, None] - planned.surface.points[None], axis=2).min(axis=1)
    assert gaps.max() < 1e-9
    fitted = np.array([g.T_object_gripper for g in plan.grasps])
    assert not np.allclose(fitted, T)  # starts, not the fitted poses


def test_training_starts_lie_on_the_surface_as_the_learned_sampler_proposes_them():
    """The regret sampler's default starts half a plan at the centre of mass; the starts that
    train a model are the surface starts the learned sampler proposes (SAMPLER_PARAMS)."""
    from isf.samplers import grasp_centre

    gripper, obj = isf.load_gripper("flat-parallel"), isf.open_object("shape:sphere")
    centre = obj.points.mean(axis=0)
    radius = np.linalg.norm(obj.points - centre, axis=1).mean()

    def start_radii(T):
        return np.linalg.norm(T[:, :3, :3] @ grasp_centre(gripper) + T[:, :3, 3] - centre, axis=1)

    trained = start_radii(plan_starts(gripper, obj, "regret", samples=8, seed=1).T_object_gripper)
    assert trained.min() > 0.5 * radius  # cluster centres: means of surface points
    from isf_sampler_learned.training import _RecordingSampler

    default = _RecordingSampler(inner=RegretSampler())
    isf.plan(gripper, obj, samples=8, sampler=default, seed=1)
    radii = start_radii(np.array([p.T_object_gripper for p in default.starts]))
    assert (radii < 0.1 * radius).sum() == 4  # what the training starts are not


def test_recording_passes_the_quality_verdict_to_a_sampler_that_hears_it():
    from isf_sampler_learned.training import _RecordingSampler

    class Hearer(RegretSampler):
        heard: list = []

        def observe(self, outcomes):
            Hearer.heard.extend(outcomes)
            super().observe(outcomes)

    recorder = _RecordingSampler(inner=Hearer(hear_quality=True))
    assert recorder.hears_quality()
    isf.plan("flat-parallel", isf.open_object("shape:box"), samples=6, sampler=recorder, seed=0)
    assert {o.holds for o in Hearer.heard if o.valid} <= {True, False}
    assert any(o.valid for o in Hearer.heard)


def test_within_object_ranking_matches_scikit_learn(tmp_path):
    from sklearn.metrics import roc_auc_score

    rng = np.random.default_rng(3)
    group = np.repeat(np.arange(4), 50)
    valid = rng.uniform(size=200) < 0.3 + 0.1 * group
    score = np.round(valid + rng.normal(scale=1.0, size=200), 1)  # informative, with ties
    valid[group == 3] = True  # one label only: no AUC for that object
    ranking = object_ranking(score, valid, group)
    expected = np.mean([roc_auc_score(valid[group == g], score[group == g]) for g in range(3)])
    assert ranking.auc == pytest.approx(expected, abs=1e-12)
    assert ranking.valid_rate == pytest.approx(np.mean([valid[group == g].mean()
                                                        for g in range(4)]))
    top = [valid[group == g][np.argsort(-score[group == g], kind="stable")[:5]].mean()
           for g in range(4)]
    assert ranking.top_decile_valid == pytest.approx(np.mean(top))
    examples = Examples(rng.uniform(size=(200, len(FEATURE_NAMES))), valid,
                        np.where(valid, 1e-3, np.inf), group)
    again = Examples.load(examples.save(tmp_path / "examples.npz"))
    for name in ("features", "valid", "error", "group"):
        np.testing.assert_array_equal(getattr(again, name), getattr(examples, name))


def test_train_command_reports_a_bad_gripper_in_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "isf_sampler_learned", "train", "--gripper",
                           str(tmp_path / "none.urdf"), "--objects", "shape:box", "--out",
                           str(tmp_path / "m.npz")], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "error:" in proc.stderr


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_grippers_find_their_shipped_model(name):
    gripper = isf.load_gripper(name)
    assert gripper_sha256(gripper) in bundled_models(), f"no model ships for {name}"
    model = load_model(bundled_models()[gripper_sha256(gripper)], gripper_sha256(gripper))
    assert model.gripper_name == name and model.info["held_out"] is not None
    json.dumps(model.info, allow_nan=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NoModelWarning)
        result = isf.plan(gripper, isf.open_object("shape:cylinder"), samples=3,
                          sampler="learned", seed=0)
    assert result.grasps[0].sampler_record["p_valid"] != 0.5
