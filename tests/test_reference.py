"""The plain-Python reference of ISF (:mod:`isf.fitting.reference`, Algorithms 1 and 2): checked
against analytic answers and finite differences, then used as the oracle of whole fits of the
compiled engine (:func:`isf.fit`, :func:`isf.fit_many`)."""

import numpy as np
import pytest
from _builders import parallel_gripper, random_rotation
from scipy.optimize import lsq_linear

import isf
from isf.config import FitConfig
from isf.fitting import reference
from isf.fitting.reference import PairBatch
from isf.fitting.segments import Segments
from isf.object.surface import ObjectSurface
from isf.result import FitStatus
from isf.se3 import exp_so3, make_transform

# ------------------------------------------------------------------ the reference on its own


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _palm_error(x, points, normals, targets, target_normals, centre, alpha):
    """E (eq. 7-9) after the motion of twist ``x = [r, u]`` about ``centre``, exactly (no
    linearisation): the function the palm step's normal equations approximate."""
    R = exp_so3(x[:3])
    moved = (points - centre) @ R.T + centre + x[3:]
    d = np.einsum("ij,ij->i", moved - targets, target_normals)
    c = np.einsum("ij,ij->i", normals @ R.T, target_normals) + 1.0
    return np.sum(d * d) + alpha**2 * np.sum(c * c)


@pytest.mark.parametrize("seed", range(3))
def test_palm_system_is_the_gradient_and_hessian_of_E(seed):
    """``-2 g`` is the finite-difference gradient of E in the twist; with zero residuals (the
    targets where the points are, normals reversed) ``2 H`` is its Hessian (Gauss-Newton exact)."""
    rng = np.random.default_rng(seed)
    alpha, h = 0.01, 1e-6
    points = rng.normal(scale=0.02, size=(60, 3))
    normals = _unit(rng.normal(size=(60, 3)))
    targets = points + rng.normal(scale=0.002, size=points.shape)
    target_normals = _unit(-normals + rng.normal(scale=0.2, size=normals.shape))
    H, g, centre = reference.palm_system(points, normals, targets, target_normals, alpha)

    def E(x):
        return _palm_error(x, points, normals, targets, target_normals, centre, alpha)

    steps = h * np.eye(6)
    gradient = np.array([(E(e) - E(-e)) / (2 * h) for e in steps])
    np.testing.assert_allclose(gradient, -2 * g, rtol=1e-6, atol=1e-12)

    H0, g0, centre0 = reference.palm_system(points, normals, points, -normals, alpha)
    np.testing.assert_allclose(g0, 0.0, atol=1e-15)

    def E0(x):
        return _palm_error(x, points, normals, points, -normals, centre0, alpha)

    hessian = np.array([[(E0(a + b) - E0(a - b) - E0(b - a) + E0(-a - b)) / (4 * h * h)
                         for b in steps] for a in steps])
    np.testing.assert_allclose(hessian, 2 * H0, rtol=1e-4, atol=1e-6 * np.abs(H0).max())


def test_palm_step_recovers_a_rigid_motion_in_steps():
    """Contact points moved off the object by a small rigid motion come back onto it by repeated
    palm steps (each the Gauss-Newton step of E)."""
    rng = np.random.default_rng(4)
    targets = rng.normal(scale=0.03, size=(200, 3))
    target_normals = _unit(rng.normal(size=(200, 3)))
    R_true, t_true = random_rotation(rng, 0.2), np.array([0.004, -0.003, 0.002])
    points, normals = (targets - t_true) @ R_true, -(target_normals @ R_true)
    T = np.eye(4)
    for _ in range(20):
        T = reference.palm_step(points @ T[:3, :3].T + T[:3, 3], normals @ T[:3, :3].T, targets,
                                target_normals, 0.01, 0.3) @ T
    np.testing.assert_allclose(T[:3, :3], R_true, atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], t_true, atol=1e-10)


@pytest.mark.parametrize("seed", range(5))
def test_box_qp_equals_bounded_least_squares(seed):
    """The active-set enumeration gives scipy's bounded-variable least squares (BVLS) answer of
    ``min ||A x - b||^2 + lam ||x||^2`` in the box."""
    rng = np.random.default_rng(seed)
    n, lam = 6, 1e-4
    A, b = rng.normal(size=(30, n)), rng.normal(size=30)
    lower, upper = -rng.uniform(0.0, 0.3, n), rng.uniform(0.0, 0.3, n)
    x = reference.box_qp(A.T @ A + lam * np.eye(n), A.T @ b, lower, upper)
    stacked = lsq_linear(np.r_[A, np.sqrt(lam) * np.eye(n)], np.r_[b, np.zeros(n)],
                         bounds=(lower, upper), method="bvls", tol=1e-14)
    np.testing.assert_allclose(x, stacked.x, atol=1e-10)
    assert np.any(x == lower) or np.any(x == upper)  # the bounds matter


def test_finger_system_is_the_gradient_of_E_in_the_joints(hand):
    """``-2 A^T b`` of the finger step is the finite-difference gradient of E in the joints
    (three-finger hand: revolute joints turn the normals, so the normal rows count)."""
    rng = np.random.default_rng(5)
    q = hand.q_initial + 0.1
    T = make_transform(random_rotation(rng, 0.3), [0.01, 0.0, 0.02])
    rows = np.arange(0, hand.n_points, 3)
    links = reference._kinematics(hand, q)
    points, normals = reference._place(hand, T, links, rows)
    targets = points + rng.normal(scale=0.002, size=points.shape)
    target_normals = _unit(-normals + rng.normal(scale=0.2, size=normals.shape))
    pairs = PairBatch(hand, Segments.single(len(rows)), rows, targets, target_normals)
    alpha = 0.01
    gripper_points, gripper_normals, offsets = reference._evaluate(pairs, links)
    _, Atb = pairs.finger_system(T[None], gripper_points, gripper_normals, offsets,
                                 reference._batch(links), alpha)

    def E(qk):
        return reference._error(pairs, T, reference._kinematics(hand, qk), alpha)

    h = 1e-6
    gradient = np.array([(E(q + h * e) - E(q - h * e)) / (2 * h) for e in np.eye(hand.n_joints)])
    np.testing.assert_allclose(gradient, -2 * Atb[0], rtol=1e-5, atol=1e-12)


def _pads_and_slab(half_gap):
    """A parallel gripper with flat square pads (normals facing each other, at ``y = -+q``) and
    the two faces of a slab at ``y = -+half_gap`` (outward normals), both sampled on grids."""
    u = np.linspace(-0.005, 0.005, 8)
    pad = np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
    pad_points = np.c_[pad[:, 0], np.zeros(len(pad)), pad[:, 1]]
    left = (pad_points, np.tile([0.0, 1.0, 0.0], (len(pad), 1)))
    right = (pad_points, np.tile([0.0, -1.0, 0.0], (len(pad), 1)))
    gripper = parallel_gripper(left, right, lower=0.0, upper=0.04, q_initial=0.012)
    v = np.linspace(-0.02, 0.02, 41)
    face = np.stack(np.meshgrid(v, v), -1).reshape(-1, 2)
    points = np.r_[np.c_[face[:, 0], np.full(len(face), -half_gap), face[:, 1]],
                   np.c_[face[:, 0], np.full(len(face), half_gap), face[:, 1]]]
    normals = np.r_[np.tile([0.0, -1.0, 0.0], (len(face), 1)),
                    np.tile([0.0, 1.0, 0.0], (len(face), 1))]
    return gripper, ObjectSurface(points, normals, spacing=0.001, name="slab")


def test_pads_close_on_a_slab_in_one_iteration_and_stay():
    """Flat pads 4 mm off the faces of a slab: the palm has nothing to correct (the gaps are
    equal), the finger step (eq. 12-13, exact for a prismatic joint) closes the jaw onto the
    faces in the first ISF iteration; the second moves nothing more (eta = 1) and each finer
    level, started in contact, stays in one iteration."""
    half_gap = 0.008
    gripper, slab = _pads_and_slab(half_gap)
    config = FitConfig()
    result = reference.fit(gripper, slab, np.eye(4), config=config)
    levels = [record.level for record in result.history]
    assert levels == [3, 3, 3, 2, 1, 0]  # the start (iteration 0), then the iterations
    assert result.status is FitStatus.CONVERGED
    np.testing.assert_allclose(result.q, [half_gap], atol=1e-12)
    np.testing.assert_allclose(result.T_object_gripper, np.eye(4), atol=1e-12)
    assert result.mean_distance < 1e-12
    assert result.history[0].n_pairs == 2 * 8  # every point of level 3 (an eighth of each pad)
    assert result.surface_contact == {"left": 1.0, "right": 1.0}
    engine = isf.fit(gripper, slab, np.eye(4), config=config)
    assert [record.level for record in engine.history] == levels


# ------------------------------------------------------------------ the engine against it


@pytest.fixture(scope="module")
def box():
    return isf.open_object("shape:box")


def _starts(gripper, n, seed=1):
    """Grasp-like starts: the gripper above the object's centre, turned and moved a little."""
    rng = np.random.default_rng(seed)
    height = -0.06 if gripper.name == "paper-parallel" else -0.05
    above = make_transform(np.eye(3), [0.0, 0.0, height])
    nudges = [make_transform(random_rotation(rng, 0.3), rng.normal(scale=0.003, size=3))
              for _ in range(n)]
    return np.stack([nudge @ above for nudge in nudges])


def _assert_same_fit(engine, expected):
    """The engine's fit follows the reference's trajectory: the same iterations per level, pairs
    and IPFO alternations in every iteration, the same status, and states equal to 1e-9 m / rad.

    E differs more than the states (relative 1e-6 allowed, about 3e-9 seen): the engine sums it
    from per-link moments (``beta2 + P . (M P - 2 v)``), which cancels digits when the fit is
    good, the reference pair by pair."""
    assert engine.status == expected.status
    shape = lambda fit: [(r.level, r.iteration, r.n_pairs, len(r.ipfo_errors))  # noqa: E731
                         for r in fit.history]
    assert shape(engine) == shape(expected)
    np.testing.assert_allclose(engine.T_object_gripper, expected.T_object_gripper, rtol=0,
                               atol=1e-9)
    np.testing.assert_allclose(engine.q, expected.q, rtol=0, atol=1e-9)
    for a, b in zip(engine.history, expected.history):
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-9)
        assert a.mean_distance == pytest.approx(b.mean_distance, rel=1e-6, abs=1e-12)
        assert a.error == pytest.approx(b.error, rel=1e-6, abs=1e-15)
        np.testing.assert_allclose(a.ipfo_errors, b.ipfo_errors, rtol=1e-6, atol=1e-15)
    assert engine.n_pairs == expected.n_pairs
    assert engine.mean_distance == pytest.approx(expected.mean_distance, rel=1e-6, abs=1e-12)
    assert engine.normal_misalignment == pytest.approx(expected.normal_misalignment, abs=1e-9)
    assert engine.error == pytest.approx(expected.error, rel=1e-6, abs=1e-15)
    np.testing.assert_allclose(engine.contact_points, expected.contact_points, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(engine.object_points, expected.object_points)
    assert engine.surface_contact == expected.surface_contact


@pytest.mark.parametrize("shape", ["cylinder", "box"])
def test_whole_fits_of_the_parallel_gripper_follow_the_reference(shape, request, paper_gripper):
    obj, gripper = request.getfixturevalue(shape), paper_gripper
    starts = _starts(gripper, 4)
    engine = isf.fit_many(gripper, obj, starts)
    assert {r.status for r in engine} >= {FitStatus.CONVERGED}
    for T, result in zip(starts, engine):
        _assert_same_fit(result, reference.fit(gripper, obj, T))


@pytest.mark.parametrize("config, shape", [
    (FitConfig(outlier_scope="fit", reject_duplicates=False, max_normal_angle=np.pi), "cylinder"),
    (FitConfig(lock_fingers=True, max_ipfo_iterations=2), "box"),
    (FitConfig(levels=2, max_iterations=30, tolerance=0.02, normal_weight=0.0, delta_e=1e-9,
               max_rotation_step=0.05, finger_damping=1e-6, outlier_factor=2.0,
               outlier_floor=0.002), "cylinder"),
], ids=["fit-scope", "locked", "other-numbers"])
def test_the_engine_follows_every_parameter_as_the_reference_does(config, shape, request,
                                                                  paper_gripper):
    """Each parameter of :class:`FitConfig` read alike. (Locked on the box: with the jaw locked
    wider than the cylinder the pads roll around it and every ISF iteration multiplies a
    difference in the state about tenfold, so two summation orders part after a few dozen
    iterations; from the width an unlocked fit ends at, the locked fits on the cylinder agree.)"""
    obj, gripper = request.getfixturevalue(shape), paper_gripper
    starts = _starts(gripper, 2, seed=3)
    for T, result in zip(starts, isf.fit_many(gripper, obj, starts, config=config)):
        expected = reference.fit(gripper, obj, T, config=config)
        _assert_same_fit(result, expected)
        if config.lock_fingers:
            np.testing.assert_array_equal(expected.q, gripper.q_initial)


def test_whole_fits_of_the_three_finger_hand_follow_the_reference(hand, cylinder):
    """Six revolute joints: the finger steps are bounded QPs (the engine's certified active set,
    the reference's enumeration of active sets)."""
    starts = _starts(hand, 3, seed=2)
    for T, result in zip(starts, isf.fit_many(hand, cylinder, starts)):
        _assert_same_fit(result, reference.fit(hand, cylinder, T))


def test_one_fit_alone_follows_the_reference(paper_gripper, box):
    (T,) = _starts(paper_gripper, 1, seed=7)
    _assert_same_fit(isf.fit(paper_gripper, box, T), reference.fit(paper_gripper, box, T))


def test_a_fit_that_loses_contact_ends_alike(paper_gripper, cylinder):
    """With ``min_pairs`` above what the coarsest level can match, both end at once with
    ``lost_contact`` and no iteration."""
    gripper = paper_gripper
    (T,) = _starts(gripper, 1)
    config = FitConfig(min_pairs=gripper.n_points)
    engine, expected = isf.fit(gripper, cylinder, T, config=config), reference.fit(
        gripper, cylinder, T, config=config)
    assert expected.status is FitStatus.LOST_CONTACT and expected.iterations == 0
    _assert_same_fit(engine, expected)
