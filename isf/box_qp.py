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
from numba import njit

from .moment_kernels import solve_small

__all__ = ["solve_box_qps"]

MAX_ROUNDS = 10
"""Active-set rounds before a problem is left uncertified."""

KKT_TOLERANCE = 1e-9
"""Relative slack of the KKT checks (of the scale of ``|H| |x| + |c|`` and of the bounds)."""


def solve_box_qps(H: np.ndarray, c: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                  max_rounds: int = MAX_ROUNDS) -> tuple[np.ndarray, np.ndarray]:
    """Solve B box-constrained QPs ``min 1/2 x^T H x - c^T x``, ``lower <= x <= upper``.

    The first round is the unconstrained minimiser: a problem whose minimiser lies within
    its bounds is certified after one linear solve.

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
    as_float = (np.ascontiguousarray(a, dtype=float) for a in (H, c, lower, upper))
    return _solve_box_qps(*as_float, int(max_rounds), KKT_TOLERANCE)


@njit(cache=True, nogil=True, error_model="numpy")
def _solve_box_qps(H, c, lower, upper, max_rounds, tolerance):
    """:func:`solve_box_qps`, compiled: each problem on its own."""
    n_problems, n = c.shape
    x, certified = np.zeros((n_problems, n)), np.zeros(n_problems, dtype=np.bool_)
    M, rhs, guess = np.empty((n, n)), np.empty(n), np.empty(n)
    low, high = np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
    next_low, next_high = np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
    for b in range(n_problems):
        low[:], high[:] = False, False
        for _ in range(max_rounds):
            # rows of fixed coordinates become x_i = bound_i; the free rows keep H x = c
            for i in range(n):
                fixed = low[i] or high[i]
                for j in range(n):
                    M[i, j] = (1.0 if i == j else 0.0) if fixed else H[b, i, j]
                rhs[i] = lower[b, i] if low[i] else (upper[b, i] if high[i] else c[b, i])
            solve_small(M, rhs, guess)
            done = True
            for i in range(n):
                r, scale = -c[b, i], abs(c[b, i])
                for j in range(n):
                    r += H[b, i, j] * guess[j]
                    scale += abs(H[b, i, j]) * abs(guess[j])
                scale *= tolerance
                room = tolerance * (upper[b, i] - lower[b, i])
                free = not (low[i] or high[i])
                below, above = free and guess[i] < lower[b, i] - room, free and guess[i] > upper[b, i] + room
                wrong_low, wrong_high = low[i] and r < -scale, high[i] and r > scale
                done = done and not (below or above or wrong_low or wrong_high)
                next_low[i] = (low[i] and not wrong_low) or below
                next_high[i] = (high[i] and not wrong_high) or above
            for i in range(n):
                x[b, i] = min(max(guess[i], lower[b, i]), upper[b, i])
            if done:
                certified[b] = True
                break
            low[:], high[:] = next_low, next_high
    return x, certified
