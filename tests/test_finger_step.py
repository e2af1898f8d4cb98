"""The finger step: a bounded QP that reduces to the paper's closed form (12)-(13) for one DoF."""

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from _builders import parallel_gripper, random_rotation
from isf.finger_step import FingerStepQP, finger_rows


def _pads(rng, n=40):
    left = (rng.uniform(-0.01, 0.01, (n, 3)), np.tile([0.0, 1.0, 0.0], (n, 1)))
    right = (rng.uniform(-0.01, 0.01, (n, 3)), np.tile([0.0, -1.0, 0.0], (n, 1)))
    return left, right


def paper_closed_form(R, t, v, points, targets, normals, finger, d0, dmin, dmax):
    """Eq. (12)-(13) written from the paper: a = 0.5 (-1)^(j-1) (Rv).n, b = (Rp + t - q).n."""
    sign = np.where(finger == 1, 1.0, -1.0)  # (-1)^(j-1) for j = 1 (left), 2 (right)
    a = 0.5 * sign * (normals @ (R @ v))
    b = np.einsum("ij,ij->i", points @ R.T + t - targets, normals)
    dd = (a @ b) / (a @ a)
    return np.clip(d0 + dd, dmin, dmax) - d0


@pytest.mark.parametrize("seed", range(20))
def test_one_dof_qp_equals_paper_closed_form(seed):
    rng = np.random.default_rng(seed)
    gripper = parallel_gripper(*_pads(rng), lower=0.005, upper=0.015, q_initial=0.01)
    q = np.array([rng.uniform(0.005, 0.015)])
    R, t = random_rotation(rng, rng.uniform(0, np.pi)), rng.normal(scale=0.01, size=3)
    kin = gripper.contact_kinematics(q)
    targets = kin.points @ R.T + t + rng.normal(scale=0.004, size=kin.points.shape)
    normals = rng.normal(size=kin.points.shape)
    normals /= np.linalg.norm(normals, axis=1)[:, None]

    A, b = finger_rows(R, kin.points @ R.T + t, kin.normals, kin.J_points, kin.J_rotation,
                       targets, normals, normal_weight=0.01)
    qp = FingerStepQP(1, damping=0.0)
    dq = qp.solve(A, b, gripper.lower - q, gripper.upper - q)

    # Paper: jaw width d = 2 q, v points from finger 1 (left, at -y) to finger 2 (right, at +y).
    finger = np.where(gripper.point_surface == 0, 1, 2)
    dd = paper_closed_form(R, t, np.array([0.0, 1.0, 0.0]), kin.points, targets, normals,
                           finger, 2 * q[0], 2 * 0.005, 2 * 0.015)
    assert dq[0] == pytest.approx(dd / 2, abs=1e-10)  # 0.1 nm: OSQP eps_abs is 1e-10


@pytest.mark.parametrize("n", [2, 6, 16])
def test_bounded_qp_matches_bvls_and_respects_bounds(n):
    rng = np.random.default_rng(n)
    qp = FingerStepQP(n, damping=0.0)
    for _ in range(10):
        A = rng.normal(size=(60, n))
        b = rng.normal(size=60)
        lower = -rng.uniform(0.0, 0.1, n)
        upper = rng.uniform(0.0, 0.1, n)
        dq = qp.solve(A, b, lower, upper)
        ref = lsq_linear(A, b, bounds=(lower, upper), method="bvls", tol=1e-14).x
        assert np.all(dq >= lower) and np.all(dq <= upper)
        np.testing.assert_allclose(dq, ref, atol=1e-8)
