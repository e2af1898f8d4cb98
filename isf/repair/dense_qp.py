"""Small dense strictly convex QPs solved exactly by the dual active-set method.

:func:`solve_dense_qp` solves

.. math::
    \\min_x\\ \\tfrac12 x^T H x + c^T x \\quad s.t.\\quad l \\le A x \\le u

for a symmetric positive definite ``H`` (n, n) and general two-sided rows ``A`` (m, n) whose
bounds may be infinite (``l_i = u_i`` makes row ``i`` an equality). It is the method of
Goldfarb and Idnani (1983, "A numerically stable dual method for solving strictly convex
quadratic programs"): start at the unconstrained minimiser ``-H^{-1} c`` (the optimum of the
dual with no constraint active), then repeatedly add the most violated constraint, dropping
active ones whose multipliers would turn negative on the way. Every step keeps the dual
feasible and raises the objective, so the method ends after finitely many steps with the
exact solution (up to rounding), or with a proof that the constraints are infeasible (a
violated constraint that no step can satisfy).

The factorisation ``J^T N = [R; 0]`` (``J = L^{-T} Q``, ``H = L L^T``, ``N`` the active
normals) is updated by Givens rotations; the loop is compiled with numba, since for the
problems it is meant for (tens of variables, a few hundred rows) interpreting it in Python
would cost more than the arithmetic.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel
from ..exceptions import InvalidInputError

__all__ = ["DenseQPResult", "solve_dense_qp"]

SOLVED, INFEASIBLE, MAX_ITER, NOT_CONVEX = 0, 1, 2, 3
_STATUS = {SOLVED: "solved", INFEASIBLE: "infeasible", MAX_ITER: "max_iter",
           NOT_CONVEX: "not_convex"}
_DEPENDENT = 1e-12  # a normal within this relative part of the active span is dependent on it


class DenseQPResult(NamedTuple):
    """Outcome of :func:`solve_dense_qp`.

    Attributes:
        x: the solution, (n,); the last iterate unless ``status == "solved"`` (NaN when
            ``"not_convex"`` or when a row's bounds cross, ``l_i > u_i``).
        y: multipliers of the rows, (m,), in OSQP's sign convention: ``H x + c + A^T y = 0``,
            ``y_i < 0`` at a lower bound, ``y_i > 0`` at an upper bound, 0 for inactive rows.
        status: ``"solved"``, ``"infeasible"`` (no ``x`` meets the rows), ``"max_iter"``
            (the step limit was reached; should not happen) or ``"not_convex"`` (``H`` is
            not positive definite).
        iterations: constraints added and dropped.
    """

    x: np.ndarray
    y: np.ndarray
    status: str
    iterations: int


def solve_dense_qp(H: np.ndarray, c: np.ndarray, A: np.ndarray | None = None,
                   l: np.ndarray | None = None, u: np.ndarray | None = None, *,
                   tolerance: float = 1e-9, max_iter: int | None = None) -> DenseQPResult:
    """Solve ``min 1/2 x^T H x + c^T x`` subject to ``l <= A x <= u`` exactly.

    Args:
        H: symmetric positive definite matrix, (n, n) (only its lower triangle is read).
        c: linear term, (n,).
        A: constraint rows, (m, n); None for none.
        l, u: their bounds, (m,) each; ``-inf`` / ``+inf`` leave a side open; None means
            all open.
        tolerance: a constraint counts as met when violated by at most ``tolerance`` times
            ``1 + |bound|`` after scaling its row to unit length.
        max_iter: at most this many steps (default ``10 (n + m) + 50``).

    Returns:
        the :class:`DenseQPResult`.

    Raises:
        InvalidInputError: inconsistent shapes or non-finite ``H``, ``c`` or ``A``.
    """
    H = np.asarray(H, dtype=float)
    c = np.asarray(c, dtype=float)
    n = len(c)
    if c.ndim != 1 or H.shape != (n, n):
        raise InvalidInputError(
            f"solve_dense_qp needs H of shape (n, n) and c of shape (n,), got {H.shape} and "
            f"{c.shape}; pass matching arrays")
    A = np.zeros((0, n)) if A is None else np.asarray(A, dtype=float)
    m = len(A)
    l = np.full(m, -np.inf) if l is None else np.asarray(l, dtype=float)
    u = np.full(m, np.inf) if u is None else np.asarray(u, dtype=float)
    if A.shape != (m, n) or l.shape != (m,) or u.shape != (m,):
        raise InvalidInputError(
            f"solve_dense_qp needs A of shape (m, {n}) and l, u of shape (m,), got {A.shape}, "
            f"{l.shape} and {u.shape}; pass one bound per row of A")
    if not (np.isfinite(H).all() and np.isfinite(c).all() and np.isfinite(A).all()):
        raise InvalidInputError("solve_dense_qp got non-finite entries in H, c or A; pass "
                                "finite arrays (only the bounds l, u may be infinite)")
    if np.isnan(l).any() or np.isnan(u).any():
        raise InvalidInputError("solve_dense_qp got NaN bounds; use -inf / +inf for open sides")
    if max_iter is None:
        max_iter = 10 * (n + m) + 50
    x, y, code, steps = _dual_active_set(np.ascontiguousarray(H), c, np.ascontiguousarray(A),
                                         l, u, float(tolerance), int(max_iter))
    return DenseQPResult(x, y, _STATUS[code], int(steps))


@kernel(error_model="python")
def _dual_active_set(H, c, A, l, u, tol, max_iter):  # pragma: no cover - compiled
    """Goldfarb-Idnani on ``l <= A x <= u``; returns ``(x, y, status, steps)``.

    Each side of a row is the one-sided constraint ``n^T x >= b`` with ``n = sign a / |a|``,
    ``b = sign bound / |a|`` (sign +1 for ``l``, -1 for ``u``); rows with ``l = u`` are
    equalities, added first and never dropped.
    """
    n, m = len(c), len(l)
    y = np.zeros(m)
    x = np.full(n, np.nan)
    inv = np.zeros(m)  # 1 / |a_i|, 0 for an all-zero row
    is_eq = np.zeros(m, dtype=np.bool_)
    n_eq = 0
    for i in range(m):
        norm = 0.0
        for j in range(n):
            norm += A[i, j] * A[i, j]
        if l[i] > u[i] or (norm == 0.0 and (l[i] > 0.0 or u[i] < 0.0)):
            return x, y, INFEASIBLE, 0
        if norm > 0.0:
            inv[i] = 1.0 / np.sqrt(norm)
            if l[i] == u[i]:
                is_eq[i] = True
                n_eq += 1
    eq_rows = np.flatnonzero(is_eq)
    # Cholesky H = L L^T (lower triangle)
    L = np.zeros((n, n))
    for j in range(n):
        s = H[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return x, y, NOT_CONVEX, 0
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = H[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    # G = J^T with J = L^{-T} Q, Q = I at the start: G = L^{-1}, by forward substitution
    G = np.zeros((n, n))
    for k in range(n):
        for i in range(k, n):
            s = 1.0 if i == k else 0.0
            for j in range(k, i):
                s -= L[i, j] * G[j, k]
            G[i, k] = s / L[i, i]
    w = np.zeros(n)
    for i in range(n):
        for j in range(n):
            w[i] += G[i, j] * c[j]
    x[:] = 0.0
    for i in range(n):
        for j in range(n):
            x[j] -= G[i, j] * w[i]  # the unconstrained minimiser -H^{-1} c
    R = np.zeros((n, n))
    act_row = np.zeros(n, dtype=np.int64)  # active constraints in factorisation order
    act_sign = np.zeros(n)
    mult = np.zeros(n + 1)  # their multipliers (mult[q] for the one being added)
    is_active = np.zeros(m, dtype=np.bool_)
    nk = np.zeros(n)
    r = np.zeros(n)
    d = np.zeros(n)
    z = np.zeros(n)
    q = 0
    steps = 0
    next_eq = 0
    while True:
        # the constraint to add: the next equality, else the most violated inequality side
        k, sk = -1, 0.0
        if next_eq < n_eq:
            k, sk = eq_rows[next_eq], 1.0
            next_eq += 1
        else:
            worst = 0.0
            for i in range(m):
                if is_active[i] or is_eq[i] or inv[i] == 0.0:
                    continue
                ax = 0.0
                for j in range(n):
                    ax += A[i, j] * x[j]
                if l[i] > -np.inf:
                    s = (ax - l[i]) * inv[i]
                    if s < -tol * (1.0 + abs(l[i]) * inv[i]) and s < worst:
                        worst, k, sk = s, i, 1.0
                if u[i] < np.inf:
                    s = (u[i] - ax) * inv[i]
                    if s < -tol * (1.0 + abs(u[i]) * inv[i]) and s < worst:
                        worst, k, sk = s, i, -1.0
        if k < 0:
            for j in range(q):
                y[act_row[j]] = -act_sign[j] * mult[j] * inv[act_row[j]]
            return x, y, SOLVED, steps
        for j in range(n):
            nk[j] = sk * A[k, j] * inv[k]
        bk = sk * (l[k] if sk > 0.0 else u[k]) * inv[k]
        mult[q] = 0.0
        while True:  # steps until constraint k is met (added) or proven impossible
            steps += 1
            if steps > max_iter:
                for j in range(q):
                    y[act_row[j]] = -act_sign[j] * mult[j] * inv[act_row[j]]
                return x, y, MAX_ITER, steps
            # d = J^T n_k; primal direction z = J2 d2 and dual direction r = R^{-1} d1
            dd = 0.0
            d2 = 0.0
            for j in range(n):
                s = 0.0
                for i in range(n):
                    s += G[j, i] * nk[i]
                d[j] = s
                dd += s * s
                if j >= q:
                    d2 += s * s
            for i in range(n):
                z[i] = 0.0
            for j in range(q, n):
                for i in range(n):
                    z[i] += d[j] * G[j, i]
            for i in range(q - 1, -1, -1):
                s = d[i]
                for j in range(i + 1, q):
                    s -= R[i, j] * r[j]
                r[i] = s / R[i, i]
            dependent = d2 <= _DEPENDENT**2 * dd
            slack = -bk
            zn = 0.0
            for i in range(n):
                slack += nk[i] * x[i]
                zn += z[i] * nk[i]
            t2 = np.inf if dependent else -slack / zn
            if is_eq[k] and dependent:
                if abs(slack) <= tol * (1.0 + abs(bk)):
                    break  # implied by the equalities already active
                return x, y, INFEASIBLE, steps
            # partial step: the first active inequality whose multiplier reaches zero
            t1, drop = np.inf, -1
            for j in range(q):
                if not is_eq[act_row[j]] and r[j] > 0.0:
                    ratio = mult[j] / r[j]
                    if ratio < t1:
                        t1, drop = ratio, j
            t = t2 if is_eq[k] else min(t1, t2)  # an equality is met in one step, either way
            if t == np.inf:
                return x, y, INFEASIBLE, steps
            if t2 < np.inf:
                for i in range(n):
                    x[i] += t * z[i]
            for j in range(q):
                mult[j] -= t * r[j]
            mult[q] += t
            if t == t2:  # constraint k is met: add it to the active set
                for j in range(n - 1, q, -1):  # rotate d[q+1:] into d[q]
                    a, bb = d[j - 1], d[j]
                    if bb == 0.0:
                        continue
                    h = np.hypot(a, bb)
                    cs, sn = a / h, bb / h
                    d[j - 1], d[j] = h, 0.0
                    _rotate(G, j - 1, j, cs, sn)
                for i in range(q + 1):
                    R[i, q] = d[i]
                act_row[q], act_sign[q] = k, sk
                is_active[k] = True
                q += 1
                break
            # drop active constraint `drop`: delete its column of R, restore the triangle
            is_active[act_row[drop]] = False
            for j in range(drop, q - 1):
                act_row[j], act_sign[j], mult[j] = act_row[j + 1], act_sign[j + 1], mult[j + 1]
                for i in range(n):
                    R[i, j] = R[i, j + 1]
            mult[q - 1] = mult[q]
            for i in range(n):
                R[i, q - 1] = 0.0
            q -= 1
            for j in range(drop, q):  # R[j+1, j] is the only entry below the diagonal
                a, bb = R[j, j], R[j + 1, j]
                if bb == 0.0:
                    continue
                h = np.hypot(a, bb)
                cs, sn = a / h, bb / h
                for col in range(j, q):
                    ra, rb = R[j, col], R[j + 1, col]
                    R[j, col] = cs * ra + sn * rb
                    R[j + 1, col] = -sn * ra + cs * rb
                R[j + 1, j] = 0.0
                _rotate(G, j, j + 1, cs, sn)


@kernel(error_model="python")
def _rotate(G, i, j, cs, sn):  # pragma: no cover - compiled
    """Rotate rows ``i`` and ``j`` of ``G`` in place: ``(cs g_i + sn g_j, -sn g_i + cs g_j)``."""
    for k in range(G.shape[1]):
        a, b = G[i, k], G[j, k]
        G[i, k] = cs * a + sn * b
        G[j, k] = -sn * a + cs * b
