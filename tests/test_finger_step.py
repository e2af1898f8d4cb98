"""The finger step: a bounded QP that reduces to the paper's closed form (12)-(13) for one DoF."""

import numpy as np
import pytest
from _builders import parallel_gripper, random_rotation
from scipy.optimize import lsq_linear

import isf
from isf.fitting._finger_step import FingerStepQP, finger_steps
from isf.fitting.reference import PairBatch
from isf.fitting.segments import Segments
from isf.se3 import make_transform


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

    pairs = PairBatch(gripper, Segments.single(gripper.n_points), np.arange(gripper.n_points), targets, normals)
    links = gripper.link_kinematics_many(q[None])
    T = make_transform(R, t)[None]
    A, b, An, _ = pairs.finger_rows(T, *pairs.evaluate(links), links, normal_weight=0.01)
    assert An is None  # a prismatic joint turns no normal
    qp = FingerStepQP(1, damping=0.0)
    dq = qp.solve(A, b, gripper.lower - q, gripper.upper - q)
    # the batched step (closed form, clipped) gives the same answer without OSQP
    AtA, Atb = pairs.finger_system(T, *pairs.evaluate(links), links, normal_weight=0.01)
    dq_batched, _ = finger_steps(AtA, Atb, (gripper.lower - q)[None], (gripper.upper - q)[None], 0.0, [qp])

    # Paper: jaw width d = 2 q, v points from finger 1 (left, at -y) to finger 2 (right, at +y).
    finger = np.where(gripper.point_surface == 0, 1, 2)
    dd = paper_closed_form(R, t, np.array([0.0, 1.0, 0.0]), kin.points, targets, normals,
                           finger, 2 * q[0], 2 * 0.005, 2 * 0.015)
    assert dq[0] == pytest.approx(dd / 2, abs=1e-10)  # 0.1 nm: OSQP eps_abs is 1e-10
    assert dq_batched[0, 0] == pytest.approx(dd / 2, abs=1e-12)


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


def test_finger_rows_are_the_derivative_of_the_residuals():
    """For revolute fingers the rows (point-to-plane and normal) equal finite differences."""
    import isf

    gripper = isf.load_gripper("three-finger")
    rng = np.random.default_rng(5)
    q = rng.uniform(gripper.lower, gripper.upper)
    T = make_transform(random_rotation(rng, 1.0), rng.normal(scale=0.05, size=3))
    index = rng.choice(gripper.n_points, 60, replace=False)
    targets = rng.normal(scale=0.05, size=(60, 3))
    normals = rng.normal(size=(60, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    pairs = PairBatch(gripper, Segments.single(60), index, targets, normals)
    alpha = 0.01

    def residuals(q):
        points, normals_g, _ = pairs.evaluate(gripper.link_kinematics_many(q[None]))
        R, t = T[:3, :3], T[:3, 3]
        d = np.einsum("kj,kj->k", points @ R.T + t - pairs.targets, pairs.target_normals)
        c = np.einsum("kj,kj->k", normals_g @ R.T, pairs.target_normals) + 1.0
        return np.r_[d, alpha * c]

    links = gripper.link_kinematics_many(q[None])
    A, b, An, bn = pairs.finger_rows(T[None], *pairs.evaluate(links), links, normal_weight=alpha)
    A, b = np.concatenate([A, An]), np.concatenate([b, bn])
    np.testing.assert_allclose(b, -residuals(q), atol=1e-15)
    h = 1e-6
    fd = np.stack([(residuals(q + h * e) - residuals(q - h * e)) / (2 * h) for e in np.eye(len(q))], axis=1)
    np.testing.assert_allclose(A, fd, atol=1e-8)


@pytest.mark.parametrize("rounds", [1, None])
def test_batched_finger_steps_equal_bvls(rounds, monkeypatch):
    """Interior minimisers come from one batched solve, bounded ones from the certified active
    set or (uncertified: forced here by allowing one active-set round) from OSQP: all equal
    BVLS."""
    import isf.fitting._box_qp

    calls = {"osqp": 0}
    if rounds is not None:
        monkeypatch.setattr(isf.fitting._box_qp, "MAX_ROUNDS", rounds)
    solve_normal = FingerStepQP.solve_normal

    def counting(self, *args):
        calls["osqp"] += 1
        return solve_normal(self, *args)

    monkeypatch.setattr(FingerStepQP, "solve_normal", counting)
    rng = np.random.default_rng(3)
    n, B = 6, 40
    A = rng.normal(size=(B, 30, n))
    b = rng.normal(size=(B, 30))
    lower = -rng.uniform(0.0, 1.0, (B, n))
    upper = rng.uniform(0.0, 1.0, (B, n))
    AtA, Atb = np.einsum("bki,bkj->bij", A, A), np.einsum("bki,bk->bi", A, b)
    qps = [FingerStepQP(n, damping=0.0) for _ in range(B)]
    dq, failed = finger_steps(AtA, Atb, lower, upper, 0.0, qps)
    assert not failed.any()
    bound_active = 0
    for k in range(B):
        ref = lsq_linear(A[k], b[k], bounds=(lower[k], upper[k]), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(dq[k], ref, atol=1e-8)
        bound_active += bool(np.any(np.isclose(ref, lower[k]) | np.isclose(ref, upper[k])))
    assert 0 < bound_active < B  # interior and bounded solutions were both exercised
    assert (calls["osqp"] > 0) == (rounds == 1)  # and OSQP only for uncertified guesses


def test_an_iterate_at_the_iteration_cap_is_kept_only_as_a_descent_step():
    """OSQP stopped by its cap: the clipped iterate is used when it lowers the QP objective."""
    rng = np.random.default_rng(8)
    n = 6
    kept = 0
    for _ in range(20):
        A = rng.normal(size=(40, n)) @ np.diag(np.logspace(0, -4, n))  # ill-conditioned
        b = rng.normal(size=40)
        lower, upper = -rng.uniform(0.0, 0.2, n), rng.uniform(0.0, 0.2, n)
        qp = FingerStepQP(n, damping=0.0, max_iter=3)
        try:
            dq = qp.solve(A, b, lower, upper)
        except isf.QPStepError:
            continue
        kept += 1
        assert np.all(dq >= lower) and np.all(dq <= upper)
        assert np.sum((A @ dq - b) ** 2) < np.sum(b**2)  # better than no step
    assert kept > 0
