"""Box-constrained strictly convex QPs solved exactly by an active-set guess with a KKT certificate.

For ``min 1/2 x^T H x - c^T x`` subject to ``lower <= x <= upper`` with ``H`` positive
definite, a point ``x`` is *the* solution exactly when the KKT conditions hold:
every free coordinate lies within its bounds with a zero gradient ``r = H x - c``, a
coordinate held at its lower bound has ``r_i >= 0`` and one held at its upper bound
``r_i <= 0``. :func:`solve_box_qps` guesses the active set (starting from the
unconstrained minimiser), solves the equality-constrained system it defines, and moves
coordinates in or out of the set (primal-dual active-set rule) for a few rounds, for
many problems at once. It returns each solution together with whether it is
certified; the caller solves the uncertified ones another way (OSQP, in
:func:`isf.finger_step.finger_steps`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["solve_box_qps"]

MAX_ROUNDS = 10
"""Active-set rounds before a problem is left uncertified."""

_KKT_TOLERANCE = 1e-9
"""Relative slack of the KKT checks (of the scale of ``|H| |x| + |c|`` and of the bounds)."""


def solve_box_qps(H: np.ndarray, c: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                  max_rounds: int = MAX_ROUNDS) -> tuple[np.ndarray, np.ndarray]:
    """Solve B box-constrained QPs ``min 1/2 x^T H x - c^T x``, ``lower <= x <= upper``.

    Args:
        H: symmetric positive definite matrices, (B, n, n).
        c: linear terms, (B, n).
        lower, upper: bounds, (B, n), ``lower <= upper``.
        max_rounds: active-set rounds at most.

    Returns:
        ``x`` (B, n), within the bounds, and ``certified`` (B,): True where ``x`` satisfies
        the KKT conditions (it is then the exact solution); elsewhere ``x`` is the last
        guess clipped into the bounds.
    """
    n_problems, n = c.shape
    eye = np.eye(n)
    x = np.empty_like(c)
    certified = np.zeros(n_problems, dtype=bool)
    at_lower = np.zeros((n_problems, n), dtype=bool)
    at_upper = np.zeros((n_problems, n), dtype=bool)
    open_ = np.arange(n_problems)  # problems not certified yet
    for _ in range(max_rounds):
        Hk, ck, lo, hi = H[open_], c[open_], lower[open_], upper[open_]
        low, high = at_lower[open_], at_upper[open_]
        fixed = low | high
        # rows of fixed coordinates become x_i = bound_i; the free rows keep H x = c
        M = np.where(fixed[:, :, None], eye, Hk)
        xk = np.linalg.solve(M, np.where(low, lo, np.where(high, hi, ck))[:, :, None])[:, :, 0]
        r = np.einsum("bij,bj->bi", Hk, xk) - ck
        scale = _KKT_TOLERANCE * (np.einsum("bij,bj->bi", np.abs(Hk), np.abs(xk)) + np.abs(ck))
        room = _KKT_TOLERANCE * (hi - lo)
        below, above = ~fixed & (xk < lo - room), ~fixed & (xk > hi + room)
        wrong_low, wrong_high = low & (r < -scale), high & (r > scale)
        done = ~np.any(below | above | wrong_low | wrong_high, axis=1)
        x[open_] = xk
        certified[open_[done]] = True
        at_lower[open_] = (low & ~wrong_low) | below
        at_upper[open_] = (high & ~wrong_high) | above
        open_ = open_[~done]
        if not len(open_):
            break
    return np.clip(x, lower, upper), certified
