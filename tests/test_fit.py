"""ISF end to end on the bundled grippers: the paper's cylinder, molds, joint limits."""

import numpy as np
import pytest
from _builders import random_rotation

import isf
from isf.config import config_from_text
from isf.se3 import make_transform, rotation_angle

GROOVE_RADIUS = 0.008  # docs/bundled-grippers.md: paper-parallel groove radius
GROOVE_HEIGHT = 0.06  # groove axis height above the palm, metres


@pytest.mark.parametrize("seed", range(5))
def test_grooves_close_on_a_cylinder(paper_gripper, seed):
    """Start 5 mm and 10 degrees off; the grooves seat on a cylinder of their own radius."""
    rng = np.random.default_rng(seed)
    obj = isf.open_object("shape:cylinder")  # radius 8 mm along x through the origin
    T_true = make_transform(np.eye(3), [0.0, 0.0, -GROOVE_HEIGHT])
    offset = rng.normal(size=3)
    T0 = make_transform(random_rotation(rng, np.radians(10)), 0.005 * offset / np.linalg.norm(offset)) @ T_true
    result = isf.fit(paper_gripper, obj, T0)
    assert result.status is isf.FitStatus.CONVERGED
    assert result.mean_distance < 0.2e-3
    # the jaw width d = 2 q between groove bottoms equals the cylinder's diameter
    assert 2 * result.q[0] == pytest.approx(2 * GROOVE_RADIUS, abs=0.2e-3)
    # the grooves' common axis lies on the cylinder axis (the x axis of the object)
    axis_point = result.T_object_gripper @ [0.0, 0.0, GROOVE_HEIGHT, 1.0]
    assert np.hypot(axis_point[1], axis_point[2]) < 0.3e-3
    assert abs(result.T_object_gripper[:3, 0] @ [1.0, 0.0, 0.0]) > np.cos(np.radians(1))


def mold(gripper, T_star, q_star, points_per_surface=3000):
    """The gripper's own contact surfaces at (T*, q*), sampled densely, as an object with flipped normals."""
    dense = isf.load_gripper(gripper.urdf_path, points_per_surface=points_per_surface)
    points, normals = dense.contact_points(q_star)
    obj = isf.ObjectSurface(points @ T_star[:3, :3].T + T_star[:3, 3], -normals @ T_star[:3, :3].T,
                            spacing=1e-3, name="mold")
    obj.surface_of_point = dense.point_surface  # which contact surface each mold point copies
    return obj


def perturbed(rng, T, angle, distance, centre=(0.0, 0.0, 0.0)):
    """``T`` turned by ``angle`` about a random axis through ``centre`` (object frame), then moved by ``distance``."""
    offset = rng.normal(size=3)
    R = random_rotation(rng, angle)
    move = make_transform(R, centre - R @ centre + distance * offset / np.linalg.norm(offset))
    return move @ T


def test_mold_paper_parallel(paper_gripper):
    """Curved grooves determine the jaw and the pose, up to sliding along the groove axis (x)."""
    rng = np.random.default_rng(0)
    T_star = perturbed(rng, np.eye(4), 1.0, 0.05)
    q_star = np.array([0.011])
    obj = mold(paper_gripper, T_star, q_star)
    centre = obj.points.mean(axis=0)
    for _ in range(3):
        start = perturbed(rng, T_star, np.radians(6), 0.002, centre)
        result = isf.fit(paper_gripper, obj, start, q=[0.01])
        # zero error up to the mold's own chord error (3000 points on an 8 mm groove: ~1 um)
        assert result.mean_distance < 3e-6
        assert result.q[0] == pytest.approx(q_star[0], abs=1e-5)
        assert rotation_angle(result.T_object_gripper[:3, :3].T @ T_star[:3, :3]) < 1e-3
        slide = np.linalg.inv(T_star) @ result.T_object_gripper
        np.testing.assert_allclose(slide[1:3, 3], 0.0, atol=5e-5)  # only x (the groove axis) is free


def test_mold_flat_parallel():
    """Flat pads determine the jaw, the pads' plane and tilt; they may slide and turn in-plane."""
    gripper = isf.load_gripper("flat-parallel")
    rng = np.random.default_rng(1)
    T_star = perturbed(rng, np.eye(4), 1.0, 0.05)
    q_star = np.array([0.025])
    obj = mold(gripper, T_star, q_star)
    centre = obj.points.mean(axis=0)
    for _ in range(3):
        result = isf.fit(gripper, obj, perturbed(rng, T_star, np.radians(5), 0.002, centre), q=[0.03])
        assert result.mean_distance < 1e-7
        assert result.q[0] == pytest.approx(q_star[0], abs=1e-6)
        relative = np.linalg.inv(T_star) @ result.T_object_gripper
        np.testing.assert_allclose(relative[:3, 1], [0.0, 1.0, 0.0], atol=1e-4)  # pad normal axis kept
        assert abs(relative[1, 3]) < 1e-5  # no motion across the pads


def _sphere_centre(points):
    """Least-squares sphere centre: |p|^2 = 2 p.c + k."""
    A = np.c_[2 * points, np.ones(len(points))]
    return np.linalg.lstsq(A, (points**2).sum(axis=1), rcond=None)[0][:3]


def test_mold_three_finger():
    """Spherical-cap pads: the fit returns every pad onto its sphere (the caps may slide on it)."""
    gripper = isf.load_gripper("three-finger")
    rng = np.random.default_rng(2)
    T_star = perturbed(rng, np.eye(4), 1.0, 0.05)
    q_star = np.array([0.1, 0.5, 0.2, 0.4, 0.0, 0.6])
    obj = mold(gripper, T_star, q_star)
    start = np.clip(q_star + rng.uniform(-0.05, 0.05, 6), gripper.lower, gripper.upper)
    result = isf.fit(gripper, obj, perturbed(rng, T_star, np.radians(3), 0.002, obj.points.mean(axis=0)), q=start)
    assert result.mean_distance < 2e-5
    T = result.T_object_gripper
    fitted = gripper.contact_points(result.q)[0] @ T[:3, :3].T + T[:3, 3]
    for k in range(len(gripper.surfaces)):
        np.testing.assert_allclose(_sphere_centre(fitted[gripper.point_surface == k]),
                                   _sphere_centre(obj.points[obj.surface_of_point == k]), atol=5e-4)


@pytest.mark.parametrize("name", ["paper-parallel", "flat-parallel", "three-finger"])
def test_joint_limits_hold_from_far_starts(name):
    """From starts far off and at the limits, the fit never leaves the joint limits."""
    gripper = isf.load_gripper(name)
    obj = isf.open_object("shape:box")
    rng = np.random.default_rng(3)
    for start in (gripper.lower, gripper.upper, gripper.q_initial):
        T0 = make_transform(random_rotation(rng, np.pi), rng.uniform(-0.02, 0.02, 3))
        result = isf.fit(gripper, obj, T0, q=start)
        qs = np.array([r.q for r in result.history] + [result.q])
        assert np.all(qs >= gripper.lower - 1e-12) and np.all(qs <= gripper.upper + 1e-12)


def test_history_records_fig5(paper_gripper):
    """The per-iteration history decreases the error overall and holds the finger displacement."""
    obj = isf.open_object("shape:cylinder")
    T0 = make_transform(random_rotation(np.random.default_rng(7), np.radians(10)), [0.0, 0.004, -0.056])
    result = isf.fit(paper_gripper, obj, T0)
    dist = [r.mean_distance for r in result.history]
    assert dist[-1] < 0.2 * dist[0]
    assert all(r.q.shape == (1,) for r in result.history)
    assert all(len(r.ipfo_errors) >= 1 for r in result.history[1:])  # [0]: the start
    assert result.iterations + 1 == len(result.history)


def test_bad_inputs_to_fit(paper_gripper):
    obj = isf.open_object("shape:cylinder")
    with pytest.raises(isf.InvalidInputError, match="4x4"):
        isf.fit(paper_gripper, obj, np.eye(3))
    with pytest.raises(isf.InvalidInputError, match="rigid transform"):
        isf.fit(paper_gripper, obj, 2 * np.eye(4))
    with pytest.raises(isf.InvalidInputError, match="outside their limits"):
        isf.fit(paper_gripper, obj, np.eye(4), q=[0.5])
    with pytest.raises(isf.InvalidInputError, match="1 finite values"):
        isf.fit(paper_gripper, obj, np.eye(4), q=[0.01, 0.01])
    for missing in ([np.nan], [None]):
        with pytest.raises(isf.InvalidInputError, match="NaN, infinite or missing"):
            isf.fit(paper_gripper, obj, np.eye(4), q=missing)
    with pytest.raises(isf.InvalidInputError, match="missing"):  # one None per pose
        isf.fit_many(paper_gripper, obj, np.stack([np.eye(4)] * 2), q=[None, None])
    with pytest.raises(isf.ConfigError, match="levels"):
        isf.FitConfig(levels=0)


def test_an_unsolvable_finger_step_is_skipped_not_fatal(monkeypatch, caplog):
    """If OSQP fails on a finger step the fit goes on moving the palm only, and says so.

    A revolute step cap of 1e-6 rad makes every joint bound active, so each finger step
    leaves the interior; with no active-set round allowed, none is certified and each goes
    to OSQP.
    """
    import isf.fitting._box_qp
    import isf.fitting._finger_step as finger_step

    def fail(self, AtA, Atb, lower, upper):
        raise isf.QPStepError({"P": AtA}, "primal infeasible")

    monkeypatch.setattr(finger_step.FingerStepQP, "solve_normal", fail)
    monkeypatch.setattr(isf.fitting._box_qp, "MAX_ROUNDS", 0)
    hand = isf.load_gripper("three-finger")
    obj = isf.open_object("shape:sphere")
    T0 = make_transform(np.eye(3), obj.centroid - [0.0, 0.0, 0.08])
    config = isf.FitConfig(max_revolute_step=1e-6, max_iterations=16)
    with caplog.at_level("WARNING", logger="isf"):
        result = isf.fit(hand, obj, T0, config=config)
    np.testing.assert_array_equal(result.q, hand.q_initial)  # the fingers never moved
    assert result.iterations > 0 and np.isfinite(result.mean_distance)
    assert "finger step skipped" in caplog.text


def test_fits_in_lockstep_equal_fits_alone(paper_gripper):
    """fit_many advances fits together; each must end exactly where it ends alone."""
    obj = isf.open_object("shape:box")
    rng = np.random.default_rng(4)
    sampler = isf.get_sampler("uniform")
    sampler.reset(obj, paper_gripper, rng)
    starts = [p.T_object_gripper for p in sampler.propose(6, rng)]
    together = isf.fit_many(paper_gripper, obj, np.stack(starts))
    for T0, batched in zip(starts, together):
        alone = isf.fit(paper_gripper, obj, T0)
        assert batched.iterations == alone.iterations and batched.status == alone.status
        np.testing.assert_allclose(batched.T_object_gripper, alone.T_object_gripper, atol=1e-12)
        np.testing.assert_allclose(batched.q, alone.q, atol=1e-12)
    assert len({r.iterations for r in together}) > 1  # the fits left the batch at different times


def test_a_gripper_without_joints_fits_by_its_palm_alone(tmp_path):
    """A rigid tool (one fixed pad, no joint): ISF moves the palm only and seats the pad on
    the box top, 7.5 mm above the box centre; the planner runs too."""
    urdf = tmp_path / "rigid.urdf"
    urdf.write_text(
        '<robot name="rigid" xmlns:isf="urn:isf:gripper:1">'
        '<link name="palm"><collision><geometry><box size="0.04 0.04 0.01"/></geometry></collision></link>'
        '<link name="pad"><collision><geometry><box size="0.01 0.01 0.002"/></geometry></collision></link>'
        '<joint name="fix" type="fixed"><parent link="palm"/><child link="pad"/>'
        '<origin xyz="0 0 0.01"/></joint>'
        '<isf:contact name="pad" link="pad" normal="0 0 1" points="64"/></robot>'
    )
    tool = isf.load_gripper(urdf)
    assert tool.n_joints == 0
    box = isf.open_object("shape:box")  # 50 x 20 x 15 mm, centred
    upside_down = make_transform(np.diag([1.0, -1.0, -1.0]), [0.003, 0.001, 0.0205])
    result = isf.fit(tool, box, upside_down)
    # the pad's top face (gripper z = 11 mm) on the box top (z = 7.5 mm): palm at z = 18.5 mm
    assert result.T_object_gripper[2, 3] == pytest.approx(0.0185, abs=1e-6)
    assert result.mean_distance < 1e-6 and result.q.shape == (0,)
    assert isf.plan(tool, box, samples=4, seed=0).stats.collision_free >= 1


def test_config_from_text_reads_each_value_as_its_field_type():
    cfg = config_from_text(isf.FitConfig, {"levels": "3", "tolerance": "0.01", "lock_fingers": "true",
                                           "outlier_scope": "fit"})
    assert cfg == isf.FitConfig(levels=3, tolerance=0.01, lock_fingers=True, outlier_scope="fit")
    assert config_from_text(isf.RepairConfig, {"max_rows": "6"}) == isf.RepairConfig(max_rows=6)


@pytest.mark.parametrize("values, message", [
    ({"max_rowz": "6"}, r"unknown RepairConfig keys \['max_rowz'\]; valid keys are"),
    ({"max_rows": "6.5"}, "RepairConfig.max_rows takes an integer, got '6.5'"),
    ({"margin": "thin"}, "RepairConfig.margin takes a number"),
    ({"lock_palm": "yes"}, "RepairConfig.lock_palm takes true or false"),
    ({"max_rows": "0"}, "RepairConfig.max_rows must be an integer >= 1"),
])
def test_config_from_text_names_a_bad_key_or_value(values, message):
    with pytest.raises(isf.ConfigError, match=message):
        config_from_text(isf.RepairConfig, values)
