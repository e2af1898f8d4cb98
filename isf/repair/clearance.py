"""Collision repair of a fitted grasp: push penetrating links out, keep the contacts.

ISF fits only the tagged contact surfaces; on a multi-fingered hand the links behind a
fingertip pad (and sometimes the palm) can end up inside the object. :func:`repair_penetration`
(or :class:`ClearanceRepair`, built once per gripper/object pair) runs a few Gauss-Newton
iterations of one small QP over the palm twist and a joint step:

.. math::
    \\min_{x, s}\\ \\sum_k \\big(m_k^T(c_k + A_k x - o_k)\\big)^2 + x^T \\Lambda x
        + w \\sum_e s_e^2
    \\quad s.t.\\quad n_i^T(p_i + A_i x - a_i) + s_{e(i)} \\ge \\mu_i,\\ s_e \\ge 0,\\
    q_{min} \\le q + \\delta q \\le q_{max},\\ |x| \\le \\Delta

with ``x = (v, w, dq)``: a palm translation ``v`` and rotation ``w`` (about the centroid of the
contacts) in the object frame, and a joint step ``dq``. ``A_i`` maps ``x`` to the motion of a
gripper point ``p_i``: ``v + w x (p_i - centre) + R J_i dq`` (``J_i`` its point Jacobian from
Pinocchio's frame Jacobian of its link, gripper frame).

* Contact rows (least squares, weight ``contact_weight``): contact-surface points ``c_k`` on the
  tangent plane ``(o_k, m_k)`` of their nearest object point, like the fit's point-to-plane rows.
  In ``pull`` mode (the default) every surface is matched afresh in each step (each surface on
  its own, the pairs of :func:`isf.fitting.correspondence.match_many` with the surfaces as groups,
  compiled in :mod:`isf.repair._contacts`), so pads that touch stay on the object and a pad the
  repair lifts off is drawn back; ``hold`` keeps the points touching at the start.
* Clearance rows (inequalities), two kinds:

  - points sampled on every link's geometry, against the object tangent plane ``(a_i, n_i)``
    that bounds them best (the largest height above the planes of the 6 nearest object
    points, as in :mod:`isf.collision.checker`; a closed mesh object is resampled densely for this).
    Only samples near the object or inside it get one: a sample farther than ``activation +
    margin`` plus twice the object's spacing, and outside, is clear of its floor by more than
    ``activation``;
  - object points inside a convex geometry element, which must leave through the element's
    nearest face (this catches an object edge poking into a link between its samples).

  ``mu_i`` is ``margin`` for links without a contact surface and ``-contact_allowance`` for the
  links that carry one (a fingertip may press into the object a little). Rows are used for
  points within ``activation`` of their floor, the deepest ``max_rows`` per element (two by
  default). One slack ``s_e`` per element (weight ``slack_weight``) keeps the QP feasible when a
  step cannot remove all penetration at once. Few rows per element is deliberate: a link across
  a thin or curved part of the object has deep points whose tangent planes face opposite ways,
  and rows from both sides, sharing one slack, cancel each other's push so the step stalls; the
  deepest two mostly lie on one side, the step moves the link out that way, and the next step
  linearises afresh (measured in ``docs/hands.md``). Only the rows that may be used, or be the
  deepest, are computed in full: a sample's 6 tangent planes are looked up only when the plane
  of its nearest dense point (a lower bound of its height) leaves it in doubt
  (``isf.repair.rows.undecided``), and an object point inside a convex element only while
  it may be among the element's ``max_rows`` deepest.
* Joint limits are hard bounds on ``q + dq``; every step is also held in a trust region.

A step that overshoots (the deepest row ends above its floor although it was violated before,
since a turning link rises faster than its linearisation) is shortened to the secant fraction that
brings that row to zero, when the shorter step is within ``tolerance``.
The best state visited is returned: least penetration first, then the smallest contact residual.
Units inside the QP are millimetres. Each QP is small and dense (tens of variables, a hundred or so
rows) and is solved exactly by daqp's dual active-set method, with OSQP as the fallback.
The gripper samples, convex elements and the dense object surface are prepared once and cached
(``isf.repair._geometry``), so a repairer is cheap to build again for the same gripper and mesh.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import daqp
import numpy as np
import osqp
import scipy.sparse as sp

from ..collision.checker import HiddenRegion, Plane, checked_state, object_voxels
from ..collision.surface_distance import NEIGHBOURS
from ..collision.voxels import kernel_arrays
from ..config import FitConfig, check_field
from ..exceptions import ConfigError, GripperDescriptionError
from ..fitting.engine import score_fit
from ..fitting.segments import Segments
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..result import FitResult
from ..se3 import exp_so3
from ._contacts import contact_pairs
from ._geometry import gripper_side, object_side
from ._step import motion_rows, step_qp, to_object
from .rows import DensePlanes, RowLimits, deepest_rows, sample_rows

__all__ = ["ClearanceRepair", "RepairConfig", "RepairResult", "repair_penetration"]

logger = logging.getLogger(__name__)

_MM = 1000.0  # QP length unit: millimetres per metre
_CONVEX_REACH = 0.003  # object points this close to a convex element (beyond its floor) get rows, m
_OUTLIER_FACTOR = 3.0  # pull mode: pairs farther than this times the median distance are dropped
_BOUND_SLACK = 1e-12  # rounding allowance on the bounds of a sample's violation, m

MIN_SPACING = 1e-4
"""Smallest ``sample_spacing`` and ``object_spacing`` of :class:`RepairConfig`, metres (denser
samples only cost memory: the clearance rows keep the deepest points)."""

DAQP_PRIMAL_TOLERANCE = 1e-12
"""daqp's primal feasibility tolerance. Its default, 1e-6, leaves the repair's rows violated by
up to 2.5e-10 mm; at 1e-12 the violations stay below 1e-14 mm at no measurable cost
(docs/benchmarks.md, "bench_repair_qp")."""
_DAQP_OPTIMAL = (1, 2)  # daqp's exit flags of an optimal solution (2: one of several)


class _Contact(NamedTuple):
    """The contact points kept on (or drawn to) the object, K of them, object frame."""

    points: np.ndarray
    """(K, 3), m."""
    plane_points: np.ndarray
    """Their object points, (K, 3), m."""
    plane_normals: np.ndarray
    """Those points' outward unit normals, (K, 3)."""
    index: np.ndarray
    """Their indices among the gripper's contact points, (K,)."""


_NO_CONTACT = _Contact(np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)), np.empty(0, dtype=int))


class _Frames(NamedTuple):
    """Frames of the gripper at joints ``q``, F of them, gripper frame."""

    rotations: np.ndarray
    """(F, 3, 3)."""
    positions: np.ndarray
    """(F, 3), m."""
    jacobians: np.ndarray
    """Frame Jacobians, linear rows first, (F, 6, n_joints)."""


class _Best(NamedTuple):
    """The best state a repair has visited."""

    score: tuple[float, float]
    """(penetration beyond the tolerance, m; mean contact residual, m), compared in order."""
    T: np.ndarray
    """Palm pose, (4, 4)."""
    q: np.ndarray
    """Joints, (n_joints,)."""
    depth: float
    """Deepest violation, m."""


class _Previous(NamedTuple):
    """A repair step taken: the state before it, the step and its centre, and the deepest
    violation before it."""

    T: np.ndarray
    """Palm pose before the step, (4, 4)."""
    q: np.ndarray
    """Joints before the step, (n_joints,)."""
    x: np.ndarray
    """The step ``(v, w, dq)``, SI units."""
    centre: np.ndarray
    """The centre of its rotation, object frame, (3,), m."""
    worst: float
    """Deepest violation before it, m."""


@dataclass(frozen=True, kw_only=True)
class RepairConfig:
    """Parameters of :func:`repair_penetration` (SI units).

    Attributes:
        iterations: at most this many QP steps.
        tolerance: stop once no row is violated by more than this, metres (so links without a
            contact surface end at least ``margin - tolerance`` from the object).
        margin: clearance asked of geometry of links without a contact surface, metres.
        contact_allowance: depth the geometry of contact-surface links may reach, metres.
        activation: gripper points closer to the object than this (plus ``margin``) get a
            clearance row, metres; points farther away are ignored in that step (a step is at
            most ``max_translation_step`` long, and the next step sees what it pushed in).
        contact_reach: contact-surface points within this distance of the object are kept on
            it (``hold`` mode); the outlier floor of the pairs (``pull`` mode), metres.
        max_normal_angle: a contact point is kept only when its normal is within this angle of
            the reversed object normal, radians.
        max_translation_step: trust region of the palm translation per step, per axis, metres.
        max_rotation_step: trust region of the palm rotation per step, per axis, radians.
        max_joint_step: trust region of each revolute joint per step, radians (prismatic
            joints use ``max_translation_step``).
        sample_spacing: spacing of the points sampled on each link geometry, metres.
        max_samples: at most this many samples per geometry element (vertices come on top).
        object_spacing: a closed mesh object is resampled this densely for the clearance
            rows (its own points are kept too), metres.
        slack_weight: weight of the squared penetration an element keeps after a step, per mm^2.
        contact_weight: weight of each kept contact point's squared residual, per mm^2.
        max_rows: at most this many clearance rows per geometry element and step (the
            deepest points). More rows let points whose tangent planes face opposite ways
            constrain one link at once, and such repairs stall (see the module docs).
        regularisation: weight of squared step size, in mm^2 of contact residual per
            (mm of palm translation)^2; rotations and joints are weighted as if they moved
            points ``lever`` metres away from the axis.
        lever: length turning radians into millimetres for the regularisation, metres.
        lock_palm: keep the palm pose; only the joints move.
    """

    iterations: int = 8
    tolerance: float = 0.00025
    margin: float = 0.0005
    contact_allowance: float = 0.001
    activation: float = 0.004
    contact_reach: float = 0.004
    max_normal_angle: float = 1.5
    max_translation_step: float = 0.005
    max_rotation_step: float = 0.1
    max_joint_step: float = 0.2
    sample_spacing: float = 0.003
    max_samples: int = 200
    object_spacing: float = 0.0015
    slack_weight: float = 1e4
    contact_weight: float = 1.0
    max_rows: int = 2
    regularisation: float = 1e-2
    lever: float = 0.03
    lock_palm: bool = False

    def __post_init__(self) -> None:
        """Refuse values of the wrong type, not finite, or out of range (:class:`ConfigError`);
        the spacings have a floor and the counts a ceiling, so no setting allocates more than a
        repair can use."""
        highs = {"iterations": 1000, "max_samples": 100_000, "max_rows": 1000}
        for name, high in highs.items():
            check_field("RepairConfig", name, getattr(self, name), integer=True, low=1, high=high)
        for name in ("tolerance", "margin", "contact_allowance", "regularisation"):
            check_field("RepairConfig", name, getattr(self, name), low=0.0)
        for name in ("activation", "contact_reach", "max_normal_angle", "max_translation_step",
                     "max_rotation_step", "max_joint_step", "slack_weight", "contact_weight",
                     "lever"):
            check_field("RepairConfig", name, getattr(self, name), above=0.0)
        for name in ("sample_spacing", "object_spacing"):
            check_field("RepairConfig", name, getattr(self, name), low=MIN_SPACING)
        check_field("RepairConfig", "lock_palm", self.lock_palm, flag=True)


class RepairResult(NamedTuple):
    """Outcome of :meth:`ClearanceRepair.repair`.

    Attributes:
        T_object_gripper: repaired palm pose, (4, 4).
        q: repaired joints, (n_joints,), within the joint limits.
        depth_before: deepest estimated violation before repair, metres (how far a point is
            below its allowed level: ``-margin`` for free links, ``contact_allowance`` for
            contact links; 0 when none).
        depth_after: the same after repair, metres.
        iterations: QP steps taken.
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    depth_before: float
    depth_after: float
    iterations: int


class _Rows(NamedTuple):
    """Clearance row candidates: link index (M,), point in its link frame (M, 3), object-frame
    direction it must move along (M, 3), violation ``floor - height`` (M,) metres, element (M,)."""

    owner: np.ndarray
    local: np.ndarray
    normal: np.ndarray
    violation: np.ndarray
    element: np.ndarray


_NO_ROWS = _Rows(np.empty(0, dtype=int), np.empty((0, 3)), np.empty((0, 3)), np.empty(0),
                 np.empty(0, dtype=int))


class ClearanceRepair:
    """Repairs penetrating grasps of one gripper on one object (set up once, then cheap).

    Args:
        gripper: the gripper; all of its ``geometries`` are kept out of the object.
        obj: the object surface (points with outward normals), object frame.
        config: repair parameters; default :class:`RepairConfig()`.
        obstacles: half-spaces (:class:`isf.collision.checker.Plane`, object frame) every link is also
            kept ``margin`` above, e.g. ``[Plane.table(z)]``.
        hidden: a region no link may enter (:class:`isf.collision.checker.HiddenRegion`, e.g. a
            scene's unseen space), or None. Each link sample inside it gets a clearance row
            along the region's way out (towards the camera), asking it to move out by its depth
            plus ``margin``.

    Raises:
        GripperDescriptionError: the gripper has no link geometry.

    A repairer remembers each contact point's and gripper sample's last nearest object point
    (to start the next search from), so give each thread its own (as
    :class:`isf.planning._evaluation.SampleJudge` does).
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, config: RepairConfig | None = None,
                 *, obstacles: Sequence[Plane] = (), hidden: HiddenRegion | None = None):
        if not gripper.geometries:
            raise GripperDescriptionError(gripper.name, [
                ("it has no link geometry to keep out of the object; give its links <collision> "
                 "elements")])
        self.gripper, self.object, self.obstacles = gripper, obj, tuple(obstacles)
        self.hidden = hidden
        self.config = cfg = RepairConfig() if config is None else config
        rng = np.random.default_rng(0)  # the object's resampling, then the gripper's samples
        self._planes, self._grid, self._resampled = object_side(obj, cfg.object_spacing, rng)
        self._voxels = object_voxels(obj)  # inside/outside of a closed mesh object, else None
        self._voxel_arrays = kernel_arrays(self._voxels)
        (self._frames, self._points_link, self._element, self._owner, self._floor,
         self._sphere_owner, self._sphere_centre, self._sphere_radius, self._convex) = gripper_side(
            gripper, cfg.sample_spacing, cfg.max_samples, cfg.margin, cfg.contact_allowance, rng)
        self._contact_frames = np.array([gripper.model.getFrameId(link)
                                         for link in gripper.contact_links], dtype=int)
        self._surfaces = Segments(gripper.point_surface)  # contact points grouped by surface
        self._contact = (gripper.point_link.astype(np.int64), gripper.points_link,
                         gripper.normals_link)
        self._contact_guess = np.full(gripper.n_points, -1, np.int64)  # pull mode's last answers
        self._sample_guess = np.full(len(self._owner), -1, np.int64)  # this repair's last answers
        self._cos_limit = -np.cos(cfg.max_normal_angle) if cfg.max_normal_angle < np.pi else np.inf
        # Millimetre units in the QP: x_mm = x * scale (v in mm, w in rad, revolute dq in rad,
        # prismatic in mm); a row a (metres of height per SI unit of x) becomes a * unit (mm
        # per unit of x_mm).
        revolute = gripper.revolute
        self._scale = np.concatenate([np.full(3, _MM), np.ones(3), np.where(revolute, 1.0, _MM)])
        self._unit = _MM / self._scale
        lever_mm2 = (cfg.lever * _MM) ** 2
        self._regularisation = 2.0 * np.diag(np.concatenate([
            np.full(3, 1.0), np.full(3, lever_mm2), np.where(revolute, lever_mm2, 1.0)])
            * cfg.regularisation)
        self._step = np.concatenate([  # trust region of x_mm
            np.full(3, 0.0 if cfg.lock_palm else cfg.max_translation_step * _MM),
            np.full(3, 0.0 if cfg.lock_palm else cfg.max_rotation_step),
            np.where(revolute, cfg.max_joint_step, cfg.max_translation_step * _MM)])

    # ------------------------------------------------------------ kinematics
    def _frame_jacobians(self, q: np.ndarray, frames: np.ndarray) -> _Frames:
        """The frames ``frames`` at joints ``q`` (n_joints,)."""
        k = self.gripper.frame_kinematics_many(q[None], frames)
        (rotations,), (positions,) = k.rotations, k.positions
        (J_linear,), (J_angular,) = k.J_linear, k.J_angular
        return _Frames(rotations, positions, np.concatenate([J_linear, J_angular], axis=1))

    # ------------------------------------------------------------ object side
    def _sample_rows(self, world: np.ndarray, guess: np.ndarray, floor: np.ndarray,
                     element: np.ndarray, known: _Rows
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Clearance rows of gripper samples against the object's tangent planes.

        A sample's height above the object is that of the tangent plane (of the 6 nearest
        dense object points) that bounds it best. Only samples near the object (closer than
        ``activation`` plus ``margin`` plus twice the object's spacing: its *reach*) or inside
        it get a row: a sample beyond reach and outside has a clearance above ``activation +
        margin``, so its row could neither be used nor be violated. Inside or outside, for a
        sample beyond reach, is read from the voxels of a closed mesh object
        (:class:`isf.collision.voxels.SurfaceVoxels`) when they settle it, else from the
        tangent plane of its nearest object point. Of the near samples, those whose row is
        certainly neither among the rows a step uses nor the deepest row (see
        :func:`isf.repair.rows.undecided`; ``known`` holds the other rows of the state) are
        left out: the plane of their nearest dense point bounds their height from below, and
        only the others get their tangent planes.

        Args:
            world: the samples, object frame, (M, 3).
            guess: an object point index near each sample to search from, -1 for none (M,).
            floor, element: their floors (M,), metres, and geometry elements (M,).
            known: the state's other clearance rows.

        Returns:
            (indices (K,) of the samples kept, their plane normals (K, 3), their violations
            ``floor - height`` (K,), metres, and each sample's nearest object point (M,), -1
            where it was not searched: beyond reach and, by the voxels, outside).
        """
        obj, cfg = self.object, self.config
        reach = cfg.activation + cfg.margin + 2.0 * obj.spacing
        planes = self._planes
        planes.note_searches(len(world))
        limits = RowLimits(len(self.gripper.geometries), cfg.activation, cfg.max_rows,
                           _BOUND_SLACK, reach)
        return sample_rows(
            np.ascontiguousarray(world, dtype=np.float64), guess, floor, element, known.violation,
            known.element, limits, (obj.points, obj.normals, obj.search.tree), self._voxel_arrays,
            DensePlanes(planes.points, planes.normals, planes.tree.tree,
                        min(NEIGHBOURS, len(planes.points))),
            self._resampled)

    def penetration(self, T_object_gripper: np.ndarray, q: np.ndarray) -> float:
        """Deepest violation of the clearance rows at a state, metres (0 when none).

        See :attr:`RepairResult.depth_before` for what a violation is.
        """
        R, p, _ = self._frame_jacobians(np.asarray(q, float), self._frames)
        violation = self._violations(np.asarray(T_object_gripper, float), R, p).violation
        return float(max(0.0, violation.max())) if len(violation) else 0.0

    # ------------------------------------------------------------------ repair
    def repair(self, T_object_gripper: np.ndarray, q: np.ndarray, *,
               contacts: str = "pull") -> RepairResult:
        """Move palm and joints until no link penetrates the object (or the iterations run out).

        Args:
            T_object_gripper: fitted palm pose, (4, 4).
            q: fitted joints, (n_joints,).
            contacts: what the contact rows do: ``"pull"`` (default) matches every contact
                surface to the object afresh in each step, like an ISF iteration, so pads that
                touch stay on the object and pads the repair frees are drawn back; ``"hold"``
                keeps only the points that touch at the start on the object; ``"none"`` only
                pushes the gripper out.

        Returns:
            the :class:`RepairResult` of the best state visited: the least penetrating one
            and, among those within ``tolerance``, the one with the smallest contact residual.
            Its joints lie within the limits.

        Raises:
            ConfigError: an unknown ``contacts`` mode.
            InvalidInputError: ``T_object_gripper`` is not a finite rigid transform or ``q`` does
                not hold one finite value per joint.
        """
        if contacts not in ("pull", "hold", "none"):
            raise ConfigError(f"contacts must be 'pull', 'hold' or 'none', got {contacts!r}")
        cfg, g = self.config, self.gripper
        T, q = checked_state(g, T_object_gripper, q)
        q = g.clip(q)
        self._sample_guess[:] = -1  # the samples' searches start from their last answers
        before = held = None
        last = np.inf  # contact residual of the previous step
        best = _Best((np.inf, np.inf), T, q, np.inf)
        steps = 0
        previous = None  # the last step taken (_Previous)
        for steps in range(cfg.iterations + 1):
            R, p, J = self._frame_jacobians(q, self._frames)
            rows = self._violations(T, R, p)
            worst = float(rows.violation.max()) if len(rows.violation) else -np.inf
            if previous is not None and previous.worst > cfg.tolerance and -np.inf < worst < 0.0:
                # the exact step overshot the floor (a turning link rises faster than its
                # linearisation): try the fraction of it that brings the deepest row to zero
                fraction = previous.worst / (previous.worst - worst)
                T1, q1 = self._apply(previous.T, previous.q, fraction * previous.x, previous.centre)
                R1, p1, J1 = self._frame_jacobians(q1, self._frames)
                rows1 = self._violations(T1, R1, p1)
                if len(rows1.violation) and rows1.violation.max() <= cfg.tolerance:
                    T, q, R, p, J, rows = T1, q1, R1, p1, J1, rows1
                    worst = float(rows.violation.max())
            depth = max(0.0, worst)
            before = depth if before is None else before
            links = None if contacts == "none" else self._frame_jacobians(q, self._contact_frames)
            if contacts == "hold" and held is None:  # the held points: those touching at the start
                held = self._contact_rows(T, q, links).index
            contact = _NO_CONTACT if contacts == "none" else \
                self._contact_rows(T, q, links, held, pull=contacts == "pull")
            gaps = np.einsum("ij,ij->i", contact.points - contact.plane_points, contact.plane_normals)
            residual = float(np.abs(gaps).mean()) if len(gaps) else 0.0
            score = (max(depth - cfg.tolerance, 0.0), residual)
            if score < best.score:
                best = _Best(score, T, q, depth)
            # pull mode goes on while the contacts still improve by a tenth of the tolerance
            settled = depth <= cfg.tolerance and (
                contacts != "pull" or residual >= last - cfg.tolerance / 10)
            if settled or steps == cfg.iterations:
                break
            last = residual
            active = self._active_rows(rows.violation, rows.element)
            if not len(active) and not len(contact.points):
                break  # no row near its floor and no contact to pull: no step to take
            owner, local = rows.owner[active], rows.local[active]
            centre = contact.points.mean(axis=0) if len(contact.points) else \
                to_object(T, R, p, owner, local).mean(axis=0)
            c_rows = self._contact_jacobian_rows(T, contact, centre, links)
            a_rows = motion_rows(T, R, p, J, owner, local, centre, rows.normal[active])
            x = self._solve(c_rows, gaps, a_rows, rows.violation[active], rows.element[active], q)
            if x is None:
                break
            previous = _Previous(T, q, x, centre, worst)
            T, q = self._apply(T, q, x, centre)
        return RepairResult(best.T, best.q, float(before or 0.0), float(best.depth), steps)

    def _near_samples(self, T: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Indices of the gripper samples of elements that may be within ``activation`` of the
        object (their bounding sphere is close to it, or their centre lies inside it)."""
        obj, owner = self.object, self._sphere_owner
        centres = to_object(T, R, p, owner, self._sphere_centre)
        dist, idx = obj.nearest(centres)
        inside = np.einsum("ei,ei->e", centres - obj.points[idx], obj.normals[idx]) < 0.0
        reach = self._sphere_radius + self.config.activation + self.config.margin \
            + 2.0 * obj.spacing
        return np.flatnonzero((inside | (dist < reach))[self._element])

    def _violations(self, T: np.ndarray, R: np.ndarray, p: np.ndarray) -> _Rows:
        """The clearance row candidates at a state (link poses ``R``, ``p`` in the gripper frame)
        that a step may use or that may be the most violated one.

        Gripper surface samples below the object's tangent planes, object points inside a
        convex gripper element (pushed out through the element's nearest face), and gripper
        samples below an obstacle plane.
        """
        known = []
        if self._convex:
            known += self._convex_rows(T, R, p)
        if self.obstacles:  # every sample of every element stays above each plane
            owner, local = self._owner, self._points_link
            world = to_object(T, R, p, owner, local)
            for plane in self.obstacles:
                known.append(_Rows(owner, local, np.broadcast_to(plane.normal, local.shape),
                                   self.config.margin - plane.height(world), self._element))
        if self.hidden is not None:  # samples in the hidden region leave it along its way out
            owner, local = self._owner, self._points_link
            world = to_object(T, R, p, owner, local)
            depth = self.hidden.depth_inside(world)
            inside = np.flatnonzero(depth > 0.0)
            if len(inside):
                known.append(_Rows(owner[inside], local[inside],
                                   self.hidden.way_out(world[inside]),
                                   self.config.margin + depth[inside], self._element[inside]))
        known = _Rows(*(np.concatenate(v) for v in zip(*known))) if known else _NO_ROWS
        sel = self._near_samples(T, R, p)
        owner, local, element = self._owner[sel], self._points_link[sel], self._element[sel]
        world = to_object(T, R, p, owner, local)
        guess = self._sample_guess[sel]
        keep, normals, violation, nearest = self._sample_rows(world, guess, self._floor[sel],
                                                              element, known)
        self._sample_guess[sel] = np.where(nearest >= 0, nearest, guess)
        samples = _Rows(owner[keep], local[keep], normals, violation, element[keep])
        return _Rows(*(np.concatenate(v) for v in zip(samples, known)))

    def _convex_rows(self, T: np.ndarray, R: np.ndarray, p: np.ndarray) -> list[_Rows]:
        """Rows of the object points inside (or within reach of) each convex element, pushed out
        through the element's nearest face (:mod:`isf.collision.convex_elements`)."""
        convex = self._convex
        rows = convex.rows(T, R, p, self._grid, _CONVEX_REACH + self.config.margin,
                           self.config.max_rows)
        return [_Rows(convex.owner[rows.element], rows.foot, rows.normal,
                      convex.floor[rows.element] - rows.depth, convex.element[rows.element])]

    def _active_rows(self, violation: np.ndarray, element: np.ndarray) -> np.ndarray:
        """Rows to use: within ``activation`` of their floor, at most ``max_rows`` per element (the
        most violating ones)."""
        cfg = self.config
        return deepest_rows(violation, element, len(self.gripper.geometries), cfg.activation,
                            cfg.max_rows)

    def _contact_rows(self, T: np.ndarray, q: np.ndarray, links: _Frames,
                      held: np.ndarray | None = None, pull: bool = False) -> _Contact:
        """Contact points kept on (or drawn to) the object, with their nearest object planes.

        Args:
            T, q: the state.
            links: the contact links' rotations, origins and Jacobians at ``q``
                (``_frame_jacobians`` of ``_contact_frames``).
            held: indices of the contact points to hold; None selects them.
            pull: select every contact point that matches the object like a fit's pairs
                (:func:`isf.repair._contacts.contact_pairs`: each surface a group, with
                ``contact_reach`` as the outlier floor); else those within ``contact_reach``
                whose normals face the object normal.

        Returns:
            the kept points (:class:`_Contact`).
        """
        cfg, g, obj = self.config, self.gripper, self.object
        if pull and held is None:  # each surface on its own: a pad that lost contact is drawn back
            source, points, target = contact_pairs(
                T, links.rotations, links.positions, self._contact, self._surfaces.starts,
                (obj.points, obj.normals, obj.search.tree), self._contact_guess, _OUTLIER_FACTOR,
                cfg.contact_reach, self._cos_limit)
            target = target[source]
            return _Contact(points[source], obj.points[target], obj.normals[target], source)
        points, normals = g.contact_points(q)
        points = points @ T[:3, :3].T + T[:3, 3]
        normals = normals @ T[:3, :3].T
        dist, idx = obj.nearest(points)
        if held is None:
            cos = np.einsum("ij,ij->i", normals, obj.normals[idx])
            facing = cos <= -np.cos(cfg.max_normal_angle)
            held = np.flatnonzero((dist <= cfg.contact_reach) & facing)
        return _Contact(points[held], obj.points[idx[held]], obj.normals[idx[held]], held)

    def _contact_jacobian_rows(self, T, contact, centre, links):
        """Rows ``m^T A`` (K, 6 + n) of the kept contact points (``links`` as for
        :meth:`_contact_rows`)."""
        g = self.gripper
        sel = contact.index
        if not len(sel):
            return np.empty((0, 6 + g.n_joints))
        return motion_rows(T, links.rotations, links.positions, links.jacobians, g.point_link[sel],
                           g.points_link[sel], centre, contact.plane_normals)

    def _qp(self, c_rows, gaps, a_rows, violation, element, q):
        """The step's QP ``min 1/2 z^T H z + f^T z, lo <= A z <= hi`` over ``z = (x_mm, s)``
        (:func:`isf.repair._step.step_qp`); ``gaps`` (K,): the contact points' signed distances
        from their tangent planes, metres.

        Returns:
            (H, f, A, lo, hi, scale): ``x_mm = x * scale`` (millimetre units), ``s`` the slacks.
        """
        step, joints, g = self._step, self._scale[6:], self.gripper
        lo = np.minimum(0.0, np.maximum(-step[6:], (g.lower - q) * joints))
        hi = np.maximum(0.0, np.minimum(step[6:], (g.upper - q) * joints))
        with np.errstate(over="ignore", invalid="ignore"):  # absurd data: refused by _solvable
            H, f, A, lower, upper = step_qp(
                c_rows, gaps * _MM, a_rows, violation * _MM, element, self._unit,
                self._regularisation, self.config.contact_weight, self.config.slack_weight,
                step[:6], lo, hi)
        return H, f, A, lower, upper, self._scale

    def _solve(self, c_rows, gaps, a_rows, violation, element, q) -> np.ndarray | None:
        """One QP step ``x = (v, w, dq)`` in SI units, or None when no solver finds one.

        The QP is solved exactly by daqp; OSQP is the fallback should daqp report anything but
        an optimum (e.g. infeasible rows).
        """
        H, f, A, lower, upper, scale = self._qp(c_rows, gaps, a_rows, violation, element, q)
        nx = len(scale)
        z = _solve_exact(H, f, A, lower, upper)
        if z is None:
            z = _solve_osqp(H, f, A, lower, upper)
            if z is None:
                return None
        x = z[:nx] / scale
        if self.config.lock_palm:
            x[:6] = 0.0  # the palm bounds are zero; keep them exactly
        return x

    def _apply(self, T, q, x, centre):
        """Apply a step: rotate by ``w`` about ``centre``, translate by ``v``, add ``dq``."""
        g = self.gripper
        Rw = exp_so3(x[3:6])
        T_new = np.eye(4)
        T_new[:3, :3] = Rw @ T[:3, :3]
        T_new[:3, 3] = Rw @ (T[:3, 3] - centre) + centre + x[:3]
        return T_new, g.clip(q + x[6:])


def _solvable(H, f, A, lower, upper) -> bool:
    """False (logged) for QP data no solver can use: non-finite terms or crossed bounds (e.g.
    an obstacle plane placed absurdly far away); OSQP would print its refusal on stdout."""
    ok = (all(np.all(np.isfinite(v)) for v in (H, f, A)) and not np.any(np.isnan(lower))
          and not np.any(np.isnan(upper)) and bool(np.all(lower <= upper))
          and not np.any(lower == np.inf) and not np.any(upper == -np.inf))
    if not ok:
        logger.debug("clearance QP: data not finite or bounds crossed; no step")
    return ok


def _solve_exact(H, f, A, lower, upper) -> np.ndarray | None:
    """daqp's exact answer to ``min 1/2 z^T H z + f^T z, lower <= A z <= upper`` (H (n, n)
    positive definite, A (m, n)), or None when it reports anything but an optimum (logged)."""
    if not _solvable(H, f, A, lower, upper):
        return None
    z, _, flag, _ = daqp.solve(H, f, A, upper, lower, primal_tol=DAQP_PRIMAL_TOLERANCE)
    if flag in _DAQP_OPTIMAL and np.all(np.isfinite(z)):
        return z
    logger.debug("clearance QP: daqp exit flag %d (-1: infeasible); falling back to OSQP", flag)
    return None


def _solve_osqp(H, f, A, lower, upper) -> np.ndarray | None:
    """OSQP's answer to ``min 1/2 z^T H z + f^T z, lower <= A z <= upper``, or None on failure
    (data OSQP would refuse, with a message on stdout, is refused here first)."""
    if not _solvable(H, f, A, lower, upper):
        return None
    solver = osqp.OSQP(algebra="builtin")  # as isf.fitting._finger_step: no backend probing
    try:
        solver.setup(sp.csc_matrix(np.triu(H)), f, sp.csc_matrix(A), lower, upper, verbose=False,
                     eps_abs=1e-3, eps_rel=1e-3, max_iter=4000, polishing=False)
    except (osqp.OSQPException, ValueError) as exc:  # data OSQP's own checks refuse
        logger.debug("clearance QP refused by OSQP's set-up: %s", exc)
        return None
    result = solver.solve(raise_error=False)
    status = getattr(result.info, "status", "")
    # An inexact step (iteration cap) is still a descent direction for Gauss-Newton; the
    # caller keeps the best state it visits.
    if result.x is None or not np.all(np.isfinite(result.x)) or "infeasible" in str(status).lower():
        logger.debug("clearance QP failed in OSQP: %s", status)
        return None
    return result.x


def repair_penetration(gripper: Gripper, obj: ObjectSurface, fit_result: FitResult,
                       config: RepairConfig | None = None, *, fit_config: FitConfig | None = None,
                       repairer: ClearanceRepair | None = None,
                       contacts: str = "pull") -> FitResult:
    """Repair a fitted grasp whose links penetrate the object (see the module docs).

    Args:
        gripper: the gripper that was fitted.
        obj: the object it was fitted to.
        fit_result: the fit (:func:`isf.fit`).
        config: repair parameters (ignored when ``repairer`` is given).
        fit_config: the fit's parameters, for re-scoring the repaired state (default
            ``FitConfig()``).
        repairer: a :class:`ClearanceRepair` already built for this gripper and object (saves
            the set-up).
        contacts: ``"pull"``, ``"hold"`` or ``"none"`` (see :meth:`ClearanceRepair.repair`).

    Returns:
        a :class:`FitResult` at the repaired pose and joints, re-scored like a fit's final state
        (:func:`isf.fitting.engine.score_fit`); ``fit_result`` itself when nothing penetrated.

    Raises:
        GripperDescriptionError: the gripper has no link geometry.
        ConfigError: an unknown ``contacts`` mode.
        InvalidInputError: the fit's pose or joints are not finite (or the pose not rigid).
    """
    repairer = ClearanceRepair(gripper, obj, config) if repairer is None else repairer
    out = repairer.repair(fit_result.T_object_gripper, fit_result.q, contacts=contacts)
    if out.iterations == 0:
        return fit_result
    return score_fit(gripper, obj, out.T_object_gripper, out.q, fit_config or FitConfig(),
                     fit_result.status, fit_result.history, fit_result.time)
