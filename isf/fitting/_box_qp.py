"""Box-constrained strictly convex QPs solved exactly by active sets, with a KKT certificate.

For ``min 1/2 x^T H x - c^T x`` subject to ``lower <= x <= upper`` with ``H`` positive
definite, a point ``x`` is *the* solution exactly when the KKT conditions hold:
every free coordinate lies within its bounds with a zero gradient ``r = H x - c``, a
coordinate held at its lower bound has ``r_i >= 0`` and one held at its upper bound
``r_i <= 0``. :func:`solve_box_qps` solves many problems at once, each in two phases that
share one budget of linear solves (``max_rounds``):

1. a primal-dual active set: guess which coordinates sit at a bound (starting from the
   unconstrained minimiser), solve the system that guess defines, move coordinates in or
   out of the set, for at most ``PRIMAL_DUAL_ROUNDS`` rounds. It is fast (one solve for
   an interior minimiser, two or three for most others) but can cycle on ill-conditioned
   problems with many active bounds (the Allegro hand's finger steps, condition numbers up
   to 5e8);
2. where that is not certified, a primal active set from the last guess clipped into the
   bounds: minimise over the free coordinates, stop at the first bound in the way and hold
   that coordinate, or, once the face's minimiser is feasible, free the held coordinate whose
   multiplier has the wrong sign. Every point it visits is feasible and the objective never
   rises, so it does not cycle on a strictly convex problem and ends in finitely many solves.

Both phases certify their answer with the same KKT test. The caller solves what is left
uncertified another way (OSQP, in :func:`isf.fitting._finger_step.finger_steps`).
"""

from __future__ import annotations

import numpy as np

from ..compiled.kernels import kernel
from ..compiled.leaf import leaf
from .moment_kernels import solve_small

__all__ = ["solve_box_qps"]

MAX_ROUNDS = 100
"""Linear solves (active-set rounds of both phases) before a problem is left uncertified."""

PRIMAL_DUAL_ROUNDS = 10
"""Rounds of the primal-dual phase at most; the primal phase has the rest of the budget."""

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
        max_rounds: linear solves per problem at most (both phases; 0 certifies nothing).

    Returns:
        ``x`` (B, n), within the bounds, and ``certified`` (B,): True where ``x`` satisfies
        the KKT conditions (it is then the exact solution); elsewhere ``x`` is the last
        feasible point reached.
    """
    as_float = (np.ascontiguousarray(a, dtype=float) for a in (H, c, lower, upper))
    return _solve_box_qps(*as_float, int(max_rounds), KKT_TOLERANCE)


@kernel
def _solve_box_qps(H, c, lower, upper, max_rounds, tolerance):
    """:func:`solve_box_qps`, compiled: each problem on its own."""
    n_problems, n = c.shape
    x, certified = np.zeros((n_problems, n)), np.zeros(n_problems, dtype=np.bool_)
    work = (np.empty((n, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
            np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_),
            np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_))
    for b in range(n_problems):
        rounds = min(max_rounds, PRIMAL_DUAL_ROUNDS)
        certified[b] = _primal_dual(H[b], c[b], lower[b], upper[b], rounds, tolerance, x[b], work)
        if not certified[b] and max_rounds > rounds:
            certified[b] = _primal(H[b], c[b], lower[b], upper[b], max_rounds - rounds, tolerance,
                                   x[b], work)
    return x, certified


@kernel(inline=True)
def _face_minimiser(H, c, lower, upper, low, high, M, rhs, guess):
    """The minimiser ``guess`` (n,) over the face where the coordinates ``low`` / ``high`` are
    held at their lower / upper bound: their rows become ``x_i = bound_i``, the free rows
    keep ``H x = c``."""
    n = len(c)
    for i in range(n):
        fixed = low[i] or high[i]
        for j in range(n):
            M[i, j] = (1.0 if i == j else 0.0) if fixed else H[i, j]
        rhs[i] = lower[i] if low[i] else (upper[i] if high[i] else c[i])
    solve_small(M, rhs, guess)


@kernel(inline=True)
def _gradient(H, c, x, tolerance, r, scale):
    """The gradient ``r = H x - c`` (n,) and the KKT test's slack ``scale`` (n,) on it."""
    n = len(c)
    for i in range(n):
        r[i], scale[i] = -c[i], abs(c[i])
        for j in range(n):
            r[i] += H[i, j] * x[j]
            scale[i] += abs(H[i, j]) * abs(x[j])
        scale[i] *= tolerance


@leaf
def _primal_dual(H, c, lower, upper, max_rounds, tolerance, x, work):
    """Phase 1 for one problem: at most ``max_rounds`` primal-dual rounds from the free set.
    Writes the last guess clipped into the bounds to ``x`` (n,); True when it is certified."""
    M, rhs, guess, r, scale, low, high, next_low, next_high = work
    n = len(c)
    low[:], high[:] = False, False
    for _ in range(max_rounds):
        _face_minimiser(H, c, lower, upper, low, high, M, rhs, guess)
        _gradient(H, c, guess, tolerance, r, scale)
        done = True
        for i in range(n):
            room = tolerance * (upper[i] - lower[i])
            free = not (low[i] or high[i])
            below, above = free and guess[i] < lower[i] - room, free and guess[i] > upper[i] + room
            wrong_low, wrong_high = low[i] and r[i] < -scale[i], high[i] and r[i] > scale[i]
            done = done and not (below or above or wrong_low or wrong_high)
            next_low[i] = (low[i] and not wrong_low) or below
            next_high[i] = (high[i] and not wrong_high) or above
        for i in range(n):
            x[i] = min(max(guess[i], lower[i]), upper[i])
        if done:
            return True
        for i in range(n):
            low[i], high[i] = next_low[i], next_high[i]
    return False


@leaf
def _primal(H, c, lower, upper, max_solves, tolerance, x, work):
    """Phase 2 for one problem: the primal active set from the feasible point ``x`` (n,),
    holding the coordinates that sit at a bound, for at most ``max_solves`` face minimisers.
    Leaves the last point reached in ``x``; True when it is certified."""
    M, rhs, guess, r, scale, low, high, _, _ = work
    n = len(c)
    for i in range(n):
        low[i], high[i] = x[i] <= lower[i], x[i] >= upper[i] and not x[i] <= lower[i]
    for _ in range(max_solves):
        _face_minimiser(H, c, lower, upper, low, high, M, rhs, guess)
        step, block = 1.0, -1  # the longest step towards the face's minimiser that stays feasible
        for i in range(n):
            if low[i] or high[i]:
                continue
            d = guess[i] - x[i]
            if guess[i] < lower[i] and (lower[i] - x[i]) / d < step:
                step, block = (lower[i] - x[i]) / d, i
            elif guess[i] > upper[i] and (upper[i] - x[i]) / d < step:
                step, block = (upper[i] - x[i]) / d, i
        for i in range(n):
            if not (low[i] or high[i]):
                x[i] = min(max(x[i] + step * (guess[i] - x[i]), lower[i]), upper[i])
        if block >= 0:  # hold the coordinate that reached its bound
            below = guess[block] < lower[block]
            x[block] = lower[block] if below else upper[block]
            low[block], high[block] = below, not below
            continue
        # at the face's minimiser: free the held coordinate whose multiplier is most wrong
        _gradient(H, c, x, tolerance, r, scale)
        worst, release = 0.0, -1
        for i in range(n):
            wrong = -r[i] - scale[i] if low[i] else (r[i] - scale[i] if high[i] else 0.0)
            if wrong > worst and upper[i] > lower[i]:
                worst, release = wrong, i
        if release < 0:
            return True
        low[release], high[release] = False, False
    return False
