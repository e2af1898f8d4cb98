"""The compiled arithmetic of a repair step (isf.repair._step) against independent computations:
homogeneous transforms, finite differences of the real kinematics, and the QP written out with
numpy."""

import numpy as np

from isf.repair._step import motion_rows, step_qp, to_object
from isf.se3 import exp_so3, make_transform


def _random_pose(rng):
    return make_transform(exp_so3(rng.normal(size=3)), rng.normal(scale=0.05, size=3))


def _links(gripper, q):
    """Rotations (L, 3, 3), origins (L, 3) and frame Jacobians (L, 6, n) of the contact links."""
    k = gripper.link_kinematics(q)
    return k.rotations, k.positions, np.concatenate([k.J_linear, k.J_angular], axis=1)


def test_to_object_is_the_product_of_the_homogeneous_transforms(hand):
    rng = np.random.default_rng(0)
    T, q = _random_pose(rng), rng.uniform(hand.lower, hand.upper)
    R, p, _ = _links(hand, q)
    owner = rng.integers(len(R), size=50)
    local = rng.normal(scale=0.02, size=(50, 3))
    expected = [(T @ make_transform(R[o], p[o]) @ np.r_[x, 1.0])[:3] for o, x in zip(owner, local)]
    np.testing.assert_allclose(to_object(T, R, p, owner, local), expected, rtol=0, atol=1e-15)


def test_motion_rows_predict_the_motion_of_points_under_a_small_step(hand):
    """n^T A x against the real displacement of the points (palm turned about the centre and
    moved, joints stepped, kinematics recomputed) along n, for steps of 1e-6: the first-order
    terms agree, the rest is O(step^2)."""
    rng = np.random.default_rng(1)
    T, q = _random_pose(rng), 0.5 * (hand.lower + hand.upper)
    R, p, J = _links(hand, q)
    owner = rng.integers(len(R), size=30)
    local = rng.normal(scale=0.02, size=(30, 3))
    normals = rng.normal(size=(30, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    centre = rng.normal(scale=0.05, size=3)
    rows = motion_rows(T, R, p, J, owner, local, centre, normals)
    before = to_object(T, R, p, owner, local)
    for _ in range(8):
        x = 1e-6 * rng.normal(size=6 + hand.n_joints)
        turn = exp_so3(x[3:6])
        T1 = make_transform(turn @ T[:3, :3], turn @ (T[:3, 3] - centre) + centre + x[:3])
        R1, p1, _ = _links(hand, q + x[6:])
        moved = np.einsum("mi,mi->m", to_object(T1, R1, p1, owner, local) - before, normals)
        np.testing.assert_allclose(rows @ x, moved, rtol=0, atol=1e-10)  # |moved| ~ 1e-7


def test_step_qp_is_the_documented_problem():
    """H, f, A and the bounds written out with numpy from the docstring's definition."""
    rng = np.random.default_rng(2)
    nx, k, m = 9, 7, 11
    contact, residual = rng.normal(size=(k, nx)), rng.normal(size=k)
    clearance, violation = rng.normal(size=(m, nx)), rng.normal(size=m)
    element = rng.choice([5, 2, 9], size=m)  # three elements with rows, out of order
    unit = rng.uniform(0.5, 2.0, nx)
    regularisation = np.diag(rng.uniform(0.1, 1.0, nx))
    palm, lower, upper = rng.uniform(0.1, 1.0, 6), -rng.uniform(size=3), rng.uniform(size=3)
    H, f, A, lo, hi = step_qp(contact, residual, clearance, violation, element, unit,
                              regularisation, 1.5, 100.0, palm, lower, upper)
    B = contact * unit
    slacks = [2, 5, 9]  # one per element with rows, in increasing order
    ns = len(slacks)
    H_ref = np.zeros((nx + ns, nx + ns))
    H_ref[:nx, :nx] = 3.0 * B.T @ B + regularisation
    H_ref[nx:, nx:] = 200.0 * np.eye(ns)
    np.testing.assert_allclose(H, H_ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(f, np.r_[3.0 * B.T @ residual, np.zeros(ns)], rtol=1e-13,
                               atol=1e-13)
    A_ref = np.zeros((m + ns + nx, nx + ns))
    A_ref[:m, :nx] = clearance * unit
    A_ref[np.arange(m), nx + np.searchsorted(slacks, element)] = 1.0
    A_ref[m:m + ns, nx:] = np.eye(ns)
    A_ref[m + ns:, :nx] = np.eye(nx)
    np.testing.assert_array_equal(A, A_ref)
    np.testing.assert_array_equal(lo, np.r_[violation, np.zeros(ns), -palm, lower])
    np.testing.assert_array_equal(hi, np.r_[np.full(m + ns, np.inf), palm, upper])


def test_step_qp_without_contacts_or_rows_is_the_regularised_box():
    unit, regularisation = np.ones(7), 2.0 * np.eye(7)
    H, f, A, lo, hi = step_qp(np.zeros((0, 7)), np.zeros(0), np.zeros((0, 7)), np.zeros(0),
                              np.zeros(0, np.int64), unit, regularisation, 1.0, 1.0,
                              np.ones(6), -np.ones(1), np.ones(1))
    np.testing.assert_array_equal(H, regularisation)
    np.testing.assert_array_equal(f, np.zeros(7))
    np.testing.assert_array_equal(A, np.eye(7))
    np.testing.assert_array_equal(lo, -np.ones(7))
    np.testing.assert_array_equal(hi, np.ones(7))
