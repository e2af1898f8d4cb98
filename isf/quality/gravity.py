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
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import block_diag
from scipy.optimize import linprog

from .contacts import Contacts
from .wrenches import CONE_EDGES, cone_edges

__all__ = ["GRAVITY", "SIX_DIRECTIONS", "gravity_loads"]

GRAVITY = 9.81
"""Standard gravity, m/s^2."""

SIX_DIRECTIONS = {"+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
                  "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}
"""Gravity directions of a hold test, object frame, by name."""


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
    forces = cone_edges(contacts.normals, friction, edges)  # (C, E, 3)
    arms = contacts.points - np.asarray(center, dtype=float)
    torques = np.cross(arms[:, None, :], forces)
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
