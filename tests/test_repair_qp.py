"""The collision repair's exact QP step (daqp, ``isf.repair.clearance._solve_exact``) against
independent answers: closed forms, the KKT conditions and OSQP at tight tolerances."""

import daqp
import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from isf.repair.clearance import DAQP_PRIMAL_TOLERANCE, _solve_exact


def _kkt_errors(H, c, A, l, u, x, y):
    """Largest stationarity, primal, dual-sign and complementarity errors (OSQP's convention)."""
    Ax = A @ x
    stationarity = np.abs(H @ x + c + A.T @ y).max() / (1.0 + np.abs(c).max())
    primal = np.maximum(np.maximum(l - Ax, Ax - u), 0.0).max(initial=0.0)
    # y < 0 only at a finite lower bound, y > 0 only at a finite upper bound
    sign = np.maximum(np.where(np.isfinite(u), 0.0, y), np.where(np.isfinite(l), 0.0, -y))
    comp = np.abs(np.minimum(y, 0.0) * np.where(np.isfinite(l), Ax - l, 1.0)) \
        + np.abs(np.maximum(y, 0.0) * np.where(np.isfinite(u), u - Ax, 1.0))
    return stationarity, primal, sign.max(initial=0.0), comp.max(initial=0.0)


def _random_problem(rng, n=22, m=136, infinite=0.3):
    """A strictly convex QP whose rows hold at a random point, with mixed bounds and box rows
    like the clearance repair's (rows, slack rows, variable bounds)."""
    M = rng.normal(size=(n, n))
    H = M @ M.T / n + np.diag(rng.uniform(1e-2, 1e4, n))  # the repair's mixed scales
    c = rng.normal(size=n) * rng.uniform(1, 100)
    A = np.vstack([rng.normal(size=(m - n, n)), np.eye(n)])
    x0 = rng.normal(size=n)
    Ax = A @ x0
    l = Ax - rng.uniform(0.0, 1.0, m)
    u = Ax + rng.uniform(0.0, 1.0, m)
    l[rng.random(m) < infinite] = -np.inf
    u[rng.random(m) < infinite] = np.inf
    return H, c, A, l, u


def _osqp(H, c, A, l, u):
    solver = osqp.OSQP()
    solver.setup(sp.csc_matrix(np.triu(H)), c, sp.csc_matrix(A), l, u, verbose=False,
                 eps_abs=1e-10, eps_rel=1e-10, max_iter=200000, polishing=True)
    return solver.solve(raise_error=False)


def _multipliers(H, c, A, l, u):
    """daqp's row multipliers of the problem (H x + c + A^T y = 0; y < 0 at a lower bound, y > 0
    at an upper one), for the KKT certificate of the answer."""
    _, _, _, info = daqp.solve(H, c, A, u, l, primal_tol=DAQP_PRIMAL_TOLERANCE)
    return np.asarray(info["lam"])


def test_two_variables_closed_form():
    # min (x1 - 2)^2 + (x2 - 1)^2  s.t.  x1 + x2 <= 1: the projection of (2, 1) is (1, 0)
    x = _solve_exact(2.0 * np.eye(2), np.array([-4.0, -2.0]), np.array([[1.0, 1.0]]),
                     np.array([-np.inf]), np.array([1.0]))
    np.testing.assert_allclose(x, [1.0, 0.0], atol=1e-12)


def test_box_rows_match_the_clipped_closed_form():
    rng = np.random.default_rng(3)
    h, c = rng.uniform(0.1, 10.0, 8), rng.normal(size=8) * 5
    lo, hi = -np.ones(8), np.ones(8)
    x = _solve_exact(np.diag(h), c, np.eye(8), lo, hi)
    np.testing.assert_allclose(x, np.clip(-c / h, lo, hi), atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_random_problems_of_the_repair_size_meet_kkt_and_match_osqp(seed):
    rng = np.random.default_rng(seed)
    H, c, A, l, u = _random_problem(rng)
    x = _solve_exact(H, c, A, l, u)
    assert x is not None
    y = _multipliers(H, c, A, l, u)
    stationarity, primal, sign, comp = _kkt_errors(H, c, A, l, u, x, y)
    assert stationarity < 1e-9 and primal < 1e-9 and sign < 1e-12
    assert comp < 1e-8 * (1.0 + np.abs(y).max())
    ref = _osqp(H, c, A, l, u)
    assert ref.info.status == "solved"
    np.testing.assert_allclose(x, ref.x, atol=1e-6 * (1.0 + np.abs(ref.x).max()))
    objective = 0.5 * x @ H @ x + c @ x
    assert objective <= 0.5 * ref.x @ H @ ref.x + c @ ref.x + 1e-9 * (1.0 + abs(objective))


@pytest.mark.parametrize("case", ["crossing rows", "equalities", "zero row"])
def test_infeasible_problems_give_none_for_the_fallback(case):
    H, c = np.eye(2), np.zeros(2)
    if case == "crossing rows":  # x1 + x2 >= 2 and x1, x2 <= 0.5
        A, l, u = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]), np.r_[2.0, -9, -9], \
            np.r_[np.inf, 0.5, 0.5]
    elif case == "equalities":  # x1 + x2 = 1, x1 = 0, x2 = 0
        A, l, u = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]), np.r_[1.0, 0, 0], \
            np.r_[1.0, 0, 0]
    else:
        A, l, u = np.zeros((1, 2)), np.r_[1.0], np.r_[2.0]
    assert _solve_exact(H, c, A, l, u) is None
    assert _osqp(H, c, A, l, u).info.status.startswith("primal infeasible")
