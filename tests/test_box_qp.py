"""Exact box-constrained QPs (isf.fitting._box_qp) against scipy's bounded least squares."""

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from isf.fitting._box_qp import PRIMAL_DUAL_ROUNDS, solve_box_qps


def random_problems(rng, n_problems, n, rows):
    """Least-squares problems ``||A x - b||^2 + damping ||x||^2`` in QP form, with bounds
    around 0 tight enough that most minimisers leave them."""
    A = rng.normal(size=(n_problems, rows, n)) * rng.uniform(0.01, 10.0, size=(n_problems, 1, n))
    b = rng.normal(size=(n_problems, rows))
    damping = 1e-6
    H = np.einsum("bki,bkj->bij", A, A) + damping * np.eye(n)
    c = np.einsum("bki,bk->bi", A, b)
    lower = -rng.uniform(0.0, 0.3, size=(n_problems, n))
    upper = rng.uniform(0.0, 0.3, size=(n_problems, n))
    return A, b, damping, H, c, lower, upper


@pytest.mark.parametrize("n", [2, 4, 16])
def test_certified_solutions_match_bounded_least_squares(n):
    rng = np.random.default_rng(n)
    A, b, damping, H, c, lower, upper = random_problems(rng, 60, n, 3 * n)
    x, certified = solve_box_qps(H, c, lower, upper)
    assert certified.all()  # every one is certified within the budget ...
    active = 0
    for k in np.flatnonzero(certified):
        # ... and those are the bounded least-squares solution (BVLS, an independent method)
        A_aug = np.vstack([A[k], np.sqrt(damping) * np.eye(n)])
        b_aug = np.r_[b[k], np.zeros(n)]
        ref = lsq_linear(A_aug, b_aug, bounds=(lower[k], upper[k]), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(x[k], ref, atol=1e-8 * (1 + np.abs(ref).max()))
        active += np.sum(np.isclose(x[k], lower[k]) | np.isclose(x[k], upper[k]))
    assert active > 0  # the bounds did bind
    assert np.all((x >= lower) & (x <= upper))


def test_interior_minimiser_is_returned_unchanged():
    rng = np.random.default_rng(1)
    _, _, _, H, c, _, _ = random_problems(rng, 5, 3, 9)
    free = np.linalg.solve(H, c[:, :, None])[:, :, 0]
    x, certified = solve_box_qps(H, c, free - 1.0, free + 1.0)
    assert certified.all()
    np.testing.assert_allclose(x, free, rtol=1e-12)


def test_a_wrong_guess_is_not_certified():
    # one round from the unconstrained start cannot find an active set that needs two changes
    H = np.array([[[1.0, 0.9], [0.9, 1.0]]])
    c = np.array([[2.0, -1.0]])
    lower, upper = np.array([[-0.1, -0.1]]), np.array([[0.1, 0.1]])
    _, ok1 = solve_box_qps(H, c, lower, upper, max_rounds=1)
    assert not ok1[0]
    x, ok = solve_box_qps(H, c, lower, upper)
    assert ok[0]
    ref = lsq_linear(np.linalg.cholesky(H[0]).T, np.linalg.solve(np.linalg.cholesky(H[0]), c[0]),
                     bounds=(lower[0], upper[0]), method="bvls", tol=1e-14).x
    np.testing.assert_allclose(x[0], ref, atol=1e-10)


def test_problems_where_the_primal_dual_rounds_cycle_are_solved_by_the_primal_phase():
    # dense 3 x 3 problems with large off-diagonal terms: the primal-dual rounds cycle on a
    # few of them (as on the Allegro hand's ill-conditioned finger steps); the primal phase
    # must certify every one, and its answers must be the bounded least-squares solution
    rng = np.random.default_rng(0)
    L = rng.normal(size=(5000, 3, 3))
    H = np.einsum("bij,bkj->bik", L, L) + 1e-3 * np.eye(3)
    c = 3.0 * rng.normal(size=(5000, 3))
    lower, upper = -np.ones((5000, 3)), np.ones((5000, 3))
    _, by_primal_dual = solve_box_qps(H, c, lower, upper, max_rounds=PRIMAL_DUAL_ROUNDS)
    x, certified = solve_box_qps(H, c, lower, upper)
    cycled = np.flatnonzero(~by_primal_dual)
    assert len(cycled) >= 3
    assert certified.all()
    for k in [*cycled, *range(40)]:
        root = np.linalg.cholesky(H[k])  # ||root^T x - root^-1 c||^2 = 2 (1/2 x^T H x - c^T x) + const
        ref = lsq_linear(root.T, np.linalg.solve(root, c[k]), bounds=(lower[k], upper[k]),
                         method="bvls", tol=1e-14).x
        np.testing.assert_allclose(x[k], ref, atol=1e-9)
    assert np.all((x >= lower) & (x <= upper))


def test_no_budget_certifies_nothing():
    # max_rounds=0 is how tests send every finger step to OSQP
    rng = np.random.default_rng(2)
    _, _, _, H, c, lower, upper = random_problems(rng, 10, 4, 12)
    _, certified = solve_box_qps(H, c, lower, upper, max_rounds=0)
    assert not certified.any()
