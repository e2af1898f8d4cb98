"""Friction cones, the grasp wrench space, force closure and the Ferrari-Canny epsilon.

A point contact with Coulomb friction coefficient ``mu`` can push along its inward normal ``n``
with any force inside its friction cone ``{f : |f - (f.n) n| <= mu (f.n)}``. The cone is
linearised as the positive span of ``edges`` forces ``n + mu (cos a_k t1 + sin a_k t2)``,
``a_k = 2 pi k / edges`` (:func:`cone_edges`; ``t1, t2`` from :func:`tangent_basis`), each with
unit normal component, so the linearised cone lies inside the true one (touching it along the
edges; its cross-section keeps cos(pi / edges) of the radius: 71 % with the default 4 edges,
92 % with 8).

The wrench of an edge force ``f`` applied at ``p`` is ``(f, (p - c) x f / r)``: force (N) and
torque about the torque origin ``c`` (the object's centre of mass), divided by the object
radius ``r`` (metres; :func:`isf.quality.grasp_quality.object_properties` states it: the largest distance from
the centre of mass to the surface) so that forces and torques have one unit and the measure
does not depend on the object's scale (Miller & Allen 1999, GraspIt!).

The *grasp wrench space* is the convex hull of the edge wrenches of all contacts: the wrenches
the grasp can resist when the contacts' normal forces sum to at most 1 N (the L1 grasp wrench
space of Ferrari & Canny 1992). The grasp is in *force closure* when the origin lies strictly
inside it (any wrench can be resisted by squeezing hard enough); its *epsilon* quality is the
radius of the largest ball about the origin inside it, the smallest wrench (in the scaled
norm) that the grasp resists worst (Ferrari & Canny 1992, "Planning optimal grasps", ICRA;
GraspIt!'s epsilon, Miller & Allen 2004, IEEE RAM). The hull is qhull's
(:class:`scipy.spatial.ConvexHull`). DexGraspNet (Wang et al. 2023) and BODex (Chen et al.
2025) optimise differentiable force-closure energies of the same contact wrenches; the epsilon
here is the measure they approximate.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import ConvexHull, QhullError

if TYPE_CHECKING:
    from .contacts import Contacts

__all__ = ["CLOSURE_TOLERANCE", "CONE_EDGES", "WrenchSpace", "cone_edges", "contact_wrenches",
           "epsilon_quality", "force_closure", "positively_spans", "tangent_bases",
           "tangent_basis"]

CONE_EDGES = 4
"""The number of edges of each linearised friction cone (see the module docstring). A pyramid
of 4 keeps the grasp wrench space small enough to rank every valid grasp of a plan
(docs/quality.md)."""

CLOSURE_TOLERANCE = 1e-9
"""An epsilon above this counts as force closure (a ball of radius 0 is a point on the
boundary)."""


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product of 3-vectors along the last axis of ``a`` and ``b`` (broadcast), as
    :func:`numpy.cross` computes it (the same products and differences, so the same bits)
    without its per-call axis handling, which costs more than the product on a few vectors."""
    a, b = np.broadcast_arrays(a, b)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def tangent_basis(normal: np.ndarray) -> np.ndarray:
    """Two unit tangents (2, 3) completing the unit ``normal`` (3,) to a right-handed frame:
    ``t1 = normal x e`` with ``e`` the coordinate axis least aligned with the normal (the first
    of equals; for ``n = +-x`` it is ``y``), and ``t2 = normal x t1``."""
    return tangent_bases(np.asarray(normal, dtype=float)[None])[0]


def tangent_bases(normals: np.ndarray) -> np.ndarray:
    """:func:`tangent_basis` of each unit normal (C, 3): (C, 2, 3)."""
    axes = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    t1 = _cross(normals, axes)
    t1 /= np.sqrt(np.add.reduce(t1 * t1, axis=1, keepdims=True))  # np.linalg.norm's sum
    return np.stack([t1, _cross(normals, t1)], axis=1)


def cone_edges(normals: np.ndarray, friction: float, edges: int = CONE_EDGES) -> np.ndarray:
    """Edge forces of the linearised friction cones of unit inward ``normals`` (C, 3):
    (C, edges, 3), each with unit normal component (see the module docstring). With
    ``friction`` 0 every edge is the normal itself (a frictionless contact)."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    angles = 2.0 * np.pi * np.arange(edges) / edges
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (edges, 2)
    return normals[:, None, :] + friction * np.einsum("ek,ckd->ced", ring, tangent_bases(normals))


def contact_wrenches(contacts: Contacts, friction: float, center: np.ndarray, radius: float,
                     edges: int = CONE_EDGES) -> np.ndarray:
    """The edge wrenches of every contact, (C * edges, 6): force (N per N of normal force) and
    torque about ``center`` (3,) divided by ``radius`` (metres), object frame."""
    forces = cone_edges(contacts.normals, friction, edges)
    arms = np.asarray(contacts.points, dtype=float) - np.asarray(center, dtype=float)
    torques = _cross(arms[:, None, :], forces) / float(radius)
    return np.concatenate([forces, torques], axis=2).reshape(-1, 6)


class WrenchSpace:
    """The grasp wrench space of edge wrenches (W, 6) (:func:`contact_wrenches`): their convex
    hull, built once (qhull with joggled input, ``QJ``, so that the many coplanar wrenches of
    a flat patch do not stop it).

    Attributes:
        epsilon: the Ferrari-Canny epsilon: the distance from the origin to the nearest facet
            when the origin is inside the hull, else 0 (also when the wrenches span fewer than
            six dimensions: then the grasp cannot resist some wrench at all).
        force_closure: the origin lies strictly inside (epsilon > :data:`isf.quality.wrenches.CLOSURE_TOLERANCE`).
    """

    def __init__(self, wrenches: np.ndarray):
        wrenches = np.asarray(wrenches, dtype=float).reshape(-1, 6)
        self._facets = None
        self.epsilon = 0.0
        if len(wrenches) > 6 and np.linalg.matrix_rank(wrenches - wrenches.mean(axis=0)) == 6:
            try:
                facets = ConvexHull(wrenches, qhull_options="QJ").equations
            except QhullError:
                facets = None
            # facets: unit normal . x + offset <= 0 inside: -offset is the origin's distance
            if facets is not None and np.all(facets[:, -1] < 0.0):
                self._facets = facets
                self.epsilon = float(np.min(-facets[:, -1]))
        self.force_closure = self.epsilon > CLOSURE_TOLERANCE

    def reach(self, directions: np.ndarray) -> np.ndarray:
        """How far the space reaches from the origin along each wrench direction (D, 6): the
        largest ``t`` with ``t * direction`` inside, (D,); NaN for every direction when the
        grasp is not in force closure (the origin is not inside: use
        :func:`isf.quality.gravity.gravity_loads`)."""
        directions = np.asarray(directions, dtype=float).reshape(-1, 6)
        if self._facets is None:
            return np.full(len(directions), np.nan)
        rate = directions @ self._facets[:, :6].T  # (D, F): how fast the ray nears each facet
        with np.errstate(divide="ignore"):
            limit = np.where(rate > 0.0, -self._facets[:, -1] / rate, np.inf)
        return limit.min(axis=1)


def epsilon_quality(wrenches: np.ndarray) -> float:
    """The Ferrari-Canny epsilon of edge wrenches (W, 6) (:attr:`WrenchSpace.epsilon`)."""
    return WrenchSpace(wrenches).epsilon


def force_closure(wrenches: np.ndarray) -> bool:
    """True when the origin lies strictly inside the convex hull of the edge wrenches (W, 6):
    the grasp resists every wrench (:attr:`WrenchSpace.force_closure`)."""
    return WrenchSpace(wrenches).force_closure


def positively_spans(wrenches: np.ndarray, tolerance: float = 1e-9) -> bool:
    """True when non-negative combinations of the edge wrenches (W, 6) reach every wrench: the
    origin lies inside their convex hull, without building it. They positively span exactly
    when they span six dimensions and a strictly positive combination of them is zero
    (Stiemke's alternative; then any wrench, written as a combination, is made non-negative by
    adding a multiple of that one); the second test is one non-negative least squares, weights
    ``1 + x`` with ``x >= 0``, residual below ``tolerance`` times the size of the system.
    False is exact up to that tolerance (the origin is outside, or on the boundary); True may
    still have an :attr:`WrenchSpace.epsilon` below :data:`CLOSURE_TOLERANCE`."""
    wrenches = np.asarray(wrenches, dtype=float).reshape(-1, 6)
    if len(wrenches) <= 6 or np.linalg.matrix_rank(wrenches) < 6:
        return False
    target = -wrenches.sum(axis=0)
    try:
        _, residual = nnls(wrenches.T, target, maxiter=50 * len(wrenches))
    except RuntimeError:  # no convergence: not shown to span
        return False
    return bool(residual <= tolerance * (1.0 + np.abs(wrenches).sum()))
