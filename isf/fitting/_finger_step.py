"""The IPFO finger step: a bounded least-squares QP over the joint vector.

It is solved exactly by a certified active set (:mod:`isf.fitting._box_qp`); OSQP solves any step the
active set cannot certify.

With the palm fixed, moving the joints by ``dq`` moves contact point ``i`` by
``R J_i dq`` (``J_i`` its point Jacobian in the gripper frame) and turns its
normal by ``(R Jw_i dq) x n_i``. The step minimises the linearised fitting error
(rows built by :meth:`isf.fitting.reference.PairBatch.finger_rows`)

.. math::
    \\min_{\\delta q} \\|A \\delta q - b\\|^2 + \\lambda \\|\\delta q\\|^2
    \\quad s.t. \\quad q_{min} - q \\le \\delta q \\le q_{max} - q

where the rows of ``A, b`` are point-to-plane rows
:math:`(n^q_i)^T R J_i`, :math:`-(\\bar p_i - q_i)^T n^q_i` and, for joints that
turn the normals, alpha-weighted normal-alignment rows. For a 1-DoF
parallel gripper this is the paper's eq. (11) and its solution is (12)-(13).
"""

from __future__ import annotations

import logging

import numpy as np
import osqp
import scipy.sparse as sp

from ..compiled.kernels import kernel
from ..exceptions import QPStepError
from . import _box_qp as box_qp

__all__ = ["FingerStepQP", "bounded_steps", "finger_steps", "solve_uncertified"]

logger = logging.getLogger(__name__)


class FingerStepQP:
    """One OSQP problem over ``n`` joints, set up on its first solve, then updated and warm-started.

    Args:
        n: number of joints.
        damping: ``lambda``, the Tikhonov weight on ``dq``.
        max_iter: OSQP's iteration cap.
    """

    def __init__(self, n: int, damping: float, max_iter: int = 4000):
        self.n = n
        self.damping = damping
        self.max_iter = max_iter
        rows, cols = np.triu_indices(n)
        order = np.lexsort((rows, cols))  # column-major: CSC order of the upper triangle
        self._rows, self._cols = rows[order], cols[order]
        self._solver: osqp.OSQP | None = None  # most fits never need OSQP (see finger_steps)
        self._x = np.zeros(n)

    def _setup(self) -> osqp.OSQP:
        """The OSQP solver, set up on first use."""
        if self._solver is None:
            n = self.n
            indptr = np.r_[0, np.cumsum(np.bincount(self._cols, minlength=n))]
            # A dense upper-triangle pattern (explicit ones): later Px updates must
            # have the same length, and csc_matrix(dense) would drop exact zeros.
            P = sp.csc_matrix((np.ones(len(self._rows)), self._rows, indptr), shape=(n, n))
            # the builtin algebra, named: the default probes for the CUDA and MKL backends
            # by failing imports on every construction, and would take
            # whichever is installed, so the steps would depend on the machine
            self._solver = osqp.OSQP(algebra="builtin")
            self._solver.setup(
                P, np.zeros(n), sp.identity(n, format="csc"), -np.ones(n), np.ones(n),
                verbose=False, eps_abs=1e-10, eps_rel=1e-10, polishing=False, max_iter=self.max_iter,
            )
        return self._solver

    def reset(self) -> None:
        """Forget the warm start and OSQP's state (before the problem serves another fit, so
        that a fit's steps do not depend on the fits served before it)."""
        self._x = np.zeros(self.n)
        self._solver = None

    def solve(self, A: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Minimise ``||A dq - b||^2 + lambda ||dq||^2`` subject to ``lower <= dq <= upper``.

        Args:
            A: rows, shape (K, n).
            b: right-hand side, shape (K,).
            lower, upper: bounds on ``dq``, shape (n,), ``lower <= 0 <= upper``.

        Returns:
            ``dq``, shape (n,).

        Raises:
            QPStepError: OSQP did not reach ``solved``.
        """
        return self.solve_normal(A.T @ A, A.T @ b, lower, upper)

    def solve_normal(self, AtA: np.ndarray, Atb: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray) -> np.ndarray:
        """The same QP given its normal equations ``A^T A`` (n, n) and ``A^T b`` (n,)."""
        H = 2.0 * AtA
        H[np.diag_indices(self.n)] += 2.0 * self.damping
        g = -2.0 * Atb
        s = self._setup()
        s.update(Px=H[self._rows, self._cols], q=g, l=lower, u=upper)
        s.warm_start(x=np.clip(self._x, lower, upper))
        res = s.solve(raise_error=False)
        x = np.clip(res.x, lower, upper) if np.all(np.isfinite(res.x)) else None
        # "solved inaccurate" is close to the optimum. At the iteration cap (ill-conditioned
        # hands) the iterate is still kept when, clipped into the bounds, it lowers the QP's
        # objective below that of no step (0): a descent step of the linearised error, which
        # IPFO then accepts only if the true E drops. Anything else is a failure.
        usable = res.info.status in ("solved", "solved inaccurate") or (
            res.info.status == "maximum iterations reached" and x is not None
            and 0.5 * x @ H @ x + g @ x < 0.0)
        if x is None or not usable:
            raise QPStepError({"P": H, "q": g, "lb": lower, "ub": upper}, res.info.status)
        self._x = x
        return self._x.copy()


def finger_steps(
    AtA: np.ndarray,
    Atb: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    damping: float,
    qps: list[FingerStepQP],
) -> tuple[np.ndarray, np.ndarray]:
    """Solve the finger QPs of many fits at once.

    The QP is strictly convex, so when the minimiser of its objective lies inside the
    bounds it *is* the QP's solution. With one joint the bounded solution is that minimiser
    clipped (the paper's eq. 12-13), for all fits at once. With more joints every fit goes
    to the compiled active sets (:func:`isf.fitting._box_qp.solve_box_qps`), whose first round is
    that minimiser; their answer is kept where the KKT conditions certify it, and only the
    rest go to their OSQP problem (``qps[b]``, set up once per fit, updated and
    warm-started; :func:`solve_uncertified`).

    Args:
        AtA: normal matrices ``A^T A``, shape (B, n, n).
        Atb: ``A^T b``, shape (B, n).
        lower, upper: bounds on ``dq``, shape (B, n), ``lower <= 0 <= upper``.
        damping: ``lambda``, the Tikhonov weight on ``dq``.
        qps: one :class:`FingerStepQP` per fit, length B.

    Returns:
        ``dq`` (B, n) and a mask (B,) of fits whose QP OSQP could not solve (their ``dq`` is 0).
    """
    as_float = [np.ascontiguousarray(a, dtype=float) for a in (AtA, Atb, lower, upper)]
    dq, exact = bounded_steps(*as_float, float(damping), box_qp.MAX_ROUNDS, box_qp.KKT_TOLERANCE)
    return dq, solve_uncertified(dq, exact, *as_float, qps)


def solve_uncertified(dq: np.ndarray, exact: np.ndarray, AtA: np.ndarray, Atb: np.ndarray,
                      lower: np.ndarray, upper: np.ndarray, qps: list[FingerStepQP]) -> np.ndarray:
    """Replace, in place, the steps ``dq`` (B, n) not ``exact`` (B,) by OSQP's answers; a QP OSQP
    cannot solve gives no step (0, logged as a warning). Returns the mask (B,) of those."""
    failed = np.zeros(len(dq), dtype=bool)
    for b in np.flatnonzero(~exact).tolist():
        try:
            dq[b] = qps[b].solve_normal(AtA[b], Atb[b], lower[b], upper[b])
        except QPStepError as err:
            logger.warning("finger step skipped: %s", err)
            dq[b], failed[b] = 0.0, True
    return failed


@kernel
def bounded_steps(AtA, Atb, lower, upper, damping, max_rounds, kkt_tolerance):
    """The finger steps of B fits without OSQP: ``dq`` (B, n) and which are exact (B,) (the
    one-joint closed form always is; the active set where it is certified).

    Args: as :func:`finger_steps`, and ``max_rounds``, ``kkt_tolerance`` of the active set.
    """
    n_fits, n = Atb.shape
    H = np.empty((n_fits, n, n))
    for b in range(n_fits):
        trace = 0.0
        for i in range(n):
            for j in range(n):
                H[b, i, j] = AtA[b, i, j] + damping * (1.0 if i == j else 0.0)
            trace += H[b, i, i]
        ridge = 1e-14 * max(trace, 1e-300)  # for singular systems; it cannot change a well-posed answer
        for i in range(n):
            H[b, i, i] += ridge
    if n == 1:  # the paper's eq. 12-13: the minimiser, clipped
        dq = np.empty((n_fits, 1))
        for b in range(n_fits):
            dq[b, 0] = min(max(Atb[b, 0] / H[b, 0, 0], lower[b, 0]), upper[b, 0])
        return dq, np.ones(n_fits, dtype=np.bool_)
    return box_qp._solve_box_qps(H, Atb, lower, upper, max_rounds, kkt_tolerance)
