"""The largest gravity load a grasp resists, per gravity direction: a linear programme.

Gravity pulls the object's weight ``s d`` (newtons, unit direction ``d``) at its centre of mass
``c``. The grasp resists it when non-negative multiples ``lambda`` of its friction-cone edge
forces (:func:`isf.quality.wrenches.cone_edges`, unit normal component each) balance it, force
and torque about ``c``, with the normal forces of all contacts summing to at most
``max_normal_force`` (the grip force; or, with ``per_surface``, those of each contact surface:
what one finger can press)::

    maximise s  over lambda >= 0, s >= 0
    subject to  sum_j lambda_j f_j + s d = 0,   sum_j lambda_j (p_j - c) x f_j = 0,
                sum_j lambda_j <= max_normal_force   (per surface k: sum over j on k).

The optimum is the largest load in direction ``d`` (newtons), 0 when the contacts cannot
balance any load in that direction (e.g. two point contacts against a torque about the line
through them). It scales with ``max_normal_force`` and does not depend on the mass, so the
*margin* ``s / (m g)`` (multiples of the object's weight) is a ranking measure up to the stated
force and mass. With the budget on the sum, the load is also where the ray ``-s (d, 0)`` leaves
the grasp wrench space (:meth:`isf.quality.wrenches.WrenchSpace.reach`, the fast form
:func:`isf.quality.grasp_quality.grasp_quality` uses for a grasp in force closure). Solved with HiGHS
(:func:`scipy.optimize.linprog`), the directions as independent blocks of one programme.
This is the classic grasp-force optimisation under friction-cone constraints (e.g. Buss,
Hashimoto & Moore 1996; Miller & Allen's GraspIt! reports the same resisted wrench), asked for the
six gravity directions of a hold test.

Whether the contacts resist one given load ``s`` (not the largest) is the feasibility of the
same constraints at that ``s`` (:func:`resists_loads`): with a slack ``sigma >= 0`` on the budget,
a system ``A x = b, x >= 0`` that non-negative least squares (Lawson & Hanson 1974,
:func:`scipy.optimize.nnls`) solves exactly, residual zero, when it is feasible: about 0.2 ms
for the six directions of a parallel gripper's grasp, against 2.5 ms for the linear programme
above and 1 to 2 ms for the wrench space's hull. When it is not, the residual ``r = b - A x``
is a Farkas certificate that bounds the largest load from above: for every feasible ``x`` at
a load ``t``, ``r . b(t) = (A^T r) . x <= max(A^T r, 0) F`` (the budget row with its slack
sums ``x`` to ``F``), and ``r . b(t)`` is linear in ``t``. A test above the largest load, on
the face of the cone of ``A`` that the ray of the loads leaves it by, gives that load to about
1e-10 of it: :func:`isf.quality.grasp_quality.quality_rank_key` narrows margins with it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg import block_diag
from scipy.optimize import linprog, nnls

from .contacts import Contacts
from .wrenches import CONE_EDGES, _cross, cone_edges

__all__ = ["GRAVITY", "RESIDUAL_TOLERANCE", "SIX_DIRECTIONS", "gravity_loads", "resists_loads"]

GRAVITY = 9.81
"""Standard gravity, m/s^2."""

SIX_DIRECTIONS = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
                  "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
"""Gravity directions of a hold test, object frame, by name."""

RESIDUAL_TOLERANCE = 1e-9
""":func:`resists_loads` counts a load as resisted when the least-squares residual of its
balance is below this fraction of the load plus the normal-force budget (an exact solution
leaves rounding, about 1e-15 of them)."""


def _edge_forces_and_torques(contacts: Contacts, friction: float, center: np.ndarray,
                             edges: int) -> tuple[np.ndarray, np.ndarray]:
    """Edge forces (C, edges, 3) of the contacts' linearised cones and their torques about
    ``center`` (3,) (N m per N of normal force)."""
    forces = cone_edges(contacts.normals, friction, edges)
    arms = contacts.points - np.asarray(center, dtype=float)
    return forces, _cross(arms[:, None, :], forces)


def gravity_loads(contacts: Contacts, friction: float, center: np.ndarray,
                  directions: np.ndarray, max_normal_force: float,
                  edges: int = CONE_EDGES, per_surface: bool = False) -> np.ndarray:
    """The largest load (N) the contacts resist along each unit gravity direction (D, 3) pulling
    at ``center`` (3,) (the centre of mass), (D,): with the normal forces of all contacts
    summing to at most ``max_normal_force`` newtons (the grip force), or with ``per_surface``
    those of each contact surface (see the module docstring)."""
    directions = np.asarray(directions, dtype=float).reshape(-1, 3)
    if contacts.count == 0:
        return np.zeros(len(directions))
    forces, torques = _edge_forces_and_torques(contacts, friction, center, edges)
    n_vars = contacts.count * edges
    balance = np.zeros((6, n_vars + 1))
    balance[:3, :n_vars] = forces.reshape(-1, 3).T
    balance[3:, :n_vars] = torques.reshape(-1, 3).T
    groups = contacts.surface if per_surface else np.zeros(contacts.count, dtype=int)
    surfaces = np.unique(groups)
    budget = np.zeros((len(surfaces), n_vars + 1))
    edge_surface = np.repeat(groups, edges)
    for row, k in enumerate(surfaces):
        budget[row, :n_vars] = edge_surface == k
    # one programme for all directions: independent blocks, so the summed optimum is each one's
    blocks = len(directions)
    rows_eq, rows_ub = [], []
    for d in directions:
        balance[:3, -1] = d
        rows_eq.append(balance.copy())
        rows_ub.append(budget)
    cost = np.zeros(blocks * (n_vars + 1))
    cost[n_vars::n_vars + 1] = -1.0
    solved = linprog(cost, A_ub=block_diag(*rows_ub),
                     b_ub=np.full(blocks * len(surfaces), float(max_normal_force)),
                     A_eq=block_diag(*rows_eq), b_eq=np.zeros(6 * blocks), bounds=(0, None),
                     method="highs")
    if solved.status != 0:
        return np.zeros(blocks)
    return np.maximum(solved.x[n_vars::n_vars + 1], 0.0) + 0.0  # no -0.0


def resists_loads(contacts: Contacts, friction: float, center: np.ndarray, directions: np.ndarray,
                  load: float, max_normal_force: float | None, edges: int = CONE_EDGES,
                  torque_scale: float = 1.0, until_failure: bool = False) -> np.ndarray:
    """Whether the contacts resist the load ``load`` (N) along each unit gravity direction
    (D, 3) pulling at ``center`` (3,), with the normal forces of all contacts summing to at
    most ``max_normal_force`` (N): (D,) bools, True exactly where :func:`gravity_loads` is at
    least ``load`` (up to :data:`RESIDUAL_TOLERANCE`; False also where the solver does not
    converge, so a caller that must be exact re-checks the False ones). Solved as the feasibility of the module
    docstring's balance at ``s = load`` by non-negative least squares; ``torque_scale`` (metres,
    e.g. the object radius) divides the torque rows so that they weigh as the force rows. With
    ``until_failure`` the directions after the first one not resisted are not tested (False).
    With ``max_normal_force`` None the grip is unbounded: True where the contacts resist some
    positive load (any ``load`` > 0 gives the same answer), False where :func:`gravity_loads`
    is 0 whatever the grip."""
    directions = np.asarray(directions, dtype=float).reshape(-1, 3)
    if contacts.count == 0:
        return np.zeros(len(directions), dtype=bool) if load > 0 else np.ones(len(directions), bool)
    balance = _LoadBalance(contacts, friction, center, max_normal_force, edges, torque_scale)
    resisted = np.zeros(len(directions), dtype=bool)
    for k, d in enumerate(directions):
        resisted[k] = balance.resists(d, load)
        if until_failure and not resisted[k]:
            break
    return resisted


class _LoadTest(NamedTuple):
    """The answer of :meth:`_LoadBalance.test` about one load.

    Attributes:
        resisted: the load is resisted (see :func:`resists_loads`).
        bound: newtons; when resisted, the load (a lower bound of the largest load), else an
            upper bound of the largest load, at most the load (the Farkas bound of the module
            docstring).
    """

    resisted: bool
    bound: float


class _LoadBalance:
    """The feasibility system of :func:`resists_loads` for one set of contacts (at least one),
    built once and asked about many loads and directions (:meth:`resists`, :meth:`test`)."""

    def __init__(self, contacts: Contacts, friction: float, center: np.ndarray,
                 max_normal_force: float | None, edges: int, torque_scale: float):
        forces, torques = _edge_forces_and_torques(contacts, friction, center, edges)
        n_vars = contacts.count * edges
        bounded = max_normal_force is not None
        system = np.zeros((7, n_vars + 1) if bounded else (6, n_vars))  # budget, slack last
        system[:3, :n_vars] = forces.reshape(-1, 3).T
        system[3:6, :n_vars] = torques.reshape(-1, 3).T / float(torque_scale)
        self._target = np.zeros(len(system))
        if bounded:
            system[6] = 1.0
            self._target[6] = max_normal_force
        self._system, self._budget = system, (max_normal_force if bounded else 0.0)
        self._maxiter = 50 * (n_vars + 1)
        self._rounding = 4.0 * np.finfo(float).eps * len(system) * float(np.abs(system).max())

    def resists(self, direction: np.ndarray, load: float) -> bool:
        """Whether the load ``load`` (N) along the unit ``direction`` (3,) is resisted."""
        resisted, _ = self._solve(direction, load)
        return resisted

    def test(self, direction: np.ndarray, load: float) -> _LoadTest:
        """Whether the load ``load`` (N) along the unit ``direction`` (3,) is resisted, and
        what that says of the largest load in that direction: at least ``load`` when resisted,
        else at most the Farkas bound of the residual (module docstring), or ``load`` when the
        residual gives none. Only for a bounded grip (``max_normal_force`` not None)."""
        resisted, solution = self._solve(direction, load)
        if resisted or solution is None:
            return _LoadTest(resisted, float(load))
        residual = self._target - self._system @ solution
        slope = -float(np.dot(direction, residual[:3]))  # r . b(t) = slope t + budget r_budget
        if slope <= 0.0:
            return _LoadTest(False, float(load))
        # max(A^T r, 0), plus what rounding in its products could hide
        excess = (max(float((self._system.T @ residual).max()), 0.0)
                  + self._rounding * float(np.abs(residual).sum()))
        return _LoadTest(False, min(float(load),
                                    self._budget * (excess - residual[6]) / slope))

    def _solve(self, direction: np.ndarray, load: float) -> tuple[bool, np.ndarray | None]:
        """Whether ``load`` along ``direction`` is resisted, and the least-squares solution
        (None when the solver did not converge); :attr:`_target` keeps the right-hand side."""
        target = self._target
        target[:3] = -load * np.asarray(direction, dtype=float)
        try:
            solution, residual = nnls(self._system, target, maxiter=self._maxiter)
        except RuntimeError:  # no convergence (not seen in practice): False, as documented
            return False, None
        return bool(residual <= RESIDUAL_TOLERANCE * (abs(load) + self._budget)), solution
