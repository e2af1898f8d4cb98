"""Tests of isf.repair.dense_qp against independent answers: KKT conditions, OSQP, closed forms."""

import numpy as np
import osqp
import pytest
import scipy.sparse as sp

from isf.exceptions import InvalidInputError
from isf.repair.dense_qp import solve_dense_qp


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


def test_two_variables_closed_form():
    # min (x1 - 2)^2 + (x2 - 1)^2  s.t.  x1 + x2 <= 1: the projection of (2, 1) is (1, 0)
    H, c = 2.0 * np.eye(2), np.array([-4.0, -2.0])
    out = solve_dense_qp(H, c, np.array([[1.0, 1.0]]), np.array([-np.inf]), np.array([1.0]))
    assert out.status == "solved"
    np.testing.assert_allclose(out.x, [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(out.y, [2.0], atol=1e-12)  # H x + c + y a = 0 with y > 0


def test_unconstrained_and_box_rows_match_closed_forms():
    rng = np.random.default_rng(3)
    h, c = rng.uniform(0.1, 10.0, 8), rng.normal(size=8) * 5
    free = solve_dense_qp(np.diag(h), c)
    np.testing.assert_allclose(free.x, -c / h, rtol=1e-12)
    lo, hi = -np.ones(8), np.ones(8)
    box = solve_dense_qp(np.diag(h), c, np.eye(8), lo, hi)
    assert box.status == "solved"
    np.testing.assert_allclose(box.x, np.clip(-c / h, lo, hi), atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_random_problems_of_the_repair_size_meet_kkt_and_match_osqp(seed):
    rng = np.random.default_rng(seed)
    H, c, A, l, u = _random_problem(rng)
    out = solve_dense_qp(H, c, A, l, u)
    assert out.status == "solved"
    stationarity, primal, sign, comp = _kkt_errors(H, c, A, l, u, out.x, out.y)
    assert stationarity < 1e-9 and primal < 1e-9 and sign < 1e-12
    assert comp < 1e-8 * (1.0 + np.abs(out.y).max())
    ref = _osqp(H, c, A, l, u)
    assert ref.info.status == "solved"
    np.testing.assert_allclose(out.x, ref.x, atol=1e-6 * (1.0 + np.abs(ref.x).max()))
    objective = 0.5 * out.x @ H @ out.x + c @ out.x
    assert objective <= 0.5 * ref.x @ H @ ref.x + c @ ref.x + 1e-9 * (1.0 + abs(objective))


def test_degenerate_and_redundant_rows():
    rng = np.random.default_rng(7)
    n = 6
    M = rng.normal(size=(n, n))
    H, c = M @ M.T + np.eye(n), -10.0 * rng.normal(size=n)
    base = rng.normal(size=(4, n))
    # duplicated rows, a scaled copy, more rows through the point x0 than variables, a zero
    # row with open-enough bounds, a redundant equality implied by two others
    A = np.vstack([base, base[:2], 3.0 * base[2:3], rng.normal(size=(n + 3, n)),
                   np.zeros((1, n)), np.eye(n)[:2], np.eye(n)[:1] + np.eye(n)[1:2]])
    m = len(A)
    x0 = np.r_[0.5, 0.25, rng.normal(size=n - 2)]
    l = np.r_[(A @ x0)[:m - 4], -1.0, 0.5, 0.25, 0.75]
    u = np.r_[np.full(m - 4, np.inf), 1.0, 0.5, 0.25, 0.75]
    out = solve_dense_qp(H, c, A, l, u)
    assert out.status == "solved"
    stationarity, primal, sign, comp = _kkt_errors(H, c, A, l, u, out.x, out.y)
    assert stationarity < 1e-9 and primal < 1e-9 and sign < 1e-12
    assert comp < 1e-8 * (1.0 + np.abs(out.y).max())
    np.testing.assert_allclose(out.x[:2], [0.5, 0.25], atol=1e-12)
    ref = _osqp(H, c, A, l, u)
    np.testing.assert_allclose(out.x, ref.x, atol=1e-6)


@pytest.mark.parametrize("case", ["crossing rows", "crossing bounds", "equalities",
                                  "zero row"])
def test_infeasible_problems_are_reported(case):
    H, c = np.eye(2), np.zeros(2)
    if case == "crossing rows":  # x1 + x2 >= 2 and x1, x2 <= 0.5
        A, l, u = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]), np.r_[2.0, -9, -9], \
            np.r_[np.inf, 0.5, 0.5]
    elif case == "crossing bounds":
        A, l, u = np.eye(2), np.r_[1.0, 0.0], np.r_[0.0, 1.0]
    elif case == "equalities":  # x1 + x2 = 1, x1 = 0, x2 = 0
        A, l, u = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]), np.r_[1.0, 0, 0], \
            np.r_[1.0, 0, 0]
    else:
        A, l, u = np.zeros((1, 2)), np.r_[1.0], np.r_[2.0]
    out = solve_dense_qp(H, c, A, l, u)
    assert out.status == "infeasible"
    if case != "crossing bounds":  # OSQP refuses l > u at set-up
        assert _osqp(H, c, A, l, u).info.status.startswith("primal infeasible")


def test_non_convex_and_bad_input():
    assert solve_dense_qp(np.diag([1.0, -1.0]), np.zeros(2)).status == "not_convex"
    with pytest.raises(InvalidInputError, match="shape"):
        solve_dense_qp(np.eye(3), np.zeros(2))
    with pytest.raises(InvalidInputError, match="one bound per row"):
        solve_dense_qp(np.eye(2), np.zeros(2), np.eye(2), np.zeros(3), np.ones(2))
    with pytest.raises(InvalidInputError, match="non-finite"):
        solve_dense_qp(np.eye(2), np.r_[np.nan, 0.0])


@pytest.mark.parametrize("seed", range(6))
def test_the_repairs_qp_solvers_agree(monkeypatch, seed):
    """The repair's exact QP solvers (``isf.repair.clearance.QP_SOLVER``: dense_qp and daqp, a
    second implementation of the method) give the same answer, up to rounding, and meet every
    row; an infeasible QP is reported (None) by both."""
    pytest.importorskip("daqp")
    from isf.repair import clearance

    H, c, A, l, u = _random_problem(np.random.default_rng(seed))
    answers = {}
    for solver in ("dense_qp", "daqp"):
        monkeypatch.setattr(clearance, "QP_SOLVER", solver)
        answers[solver] = x = clearance._solve_exact(H, c, A, l, u)
        Ax = A @ x
        assert np.all(Ax >= l - 1e-9 * (1.0 + np.abs(l)))
        assert np.all(Ax <= u + 1e-9 * (1.0 + np.abs(u)))
        infeasible = np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([1.0, -np.inf]), \
            np.array([np.inf, 0.0])  # x1 >= 1 and x1 <= 0
        assert clearance._solve_exact(np.eye(2), np.zeros(2), *infeasible) is None
    scale = 1.0 + np.abs(answers["dense_qp"]).max()
    assert np.abs(answers["daqp"] - answers["dense_qp"]).max() <= 1e-8 * scale
