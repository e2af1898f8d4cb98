"""Settle a grasp planned on a scene: fingers opened and palm backed off until they stop short of
the observed surface by what its noise could hide.

The planner accepts a grasp whose links sit up to its collision tolerance (2 mm) inside the
surface it sees. On a complete object that surface is exact; on a scene it is a depth camera's,
smoothed, and the true surface lies up to a few of its noise widths behind or in front of it,
so a grasp at the tolerance on a scene may press 2-4 mm into the object it was planned on
(on simulated scenes, grasps the check measured 0.6-2 mm deep were 0.5-3.2 mm deep in the true
meshes).

:class:`Settler` moves each collision-free grasp out of the observed surface until its deepest
penetration (object, unseen space and table, as the planner's check) is within the *contact
allowance* ``max(0, tolerance - NOISE_MARGIN x Scene.noise)``:

* one finger (a link carrying a contact surface) too deep, and no other finger so far: the
  gripper moves against that finger's contact normal by the excess depth (the other fingers
  come closer to their surfaces instead of leaving them);
* fingers too deep on more than one side: the fingers open towards :attr:`isf.Gripper.q_open`,
  the contact points moving by the excess depth;
* any other link (the palm) too deep, or fingers that cannot open further: the gripper backs off
  along its approach direction by the excess depth.

Each move goes :data:`STEP_MARGIN` beyond the excess. When that move leaves the gripper no less
deep (an edge of a finger, not its pad, digging into a curved surface; a finger opening into
the unseen space), the gripper instead takes the least deep of the other moves by the same
length: the opening, the back-off, and a translation either way along the gripper frame's x
and y axes.

At most :data:`SETTLE_STEPS` moves are made; the settled state is scored afresh
(:func:`isf.fitting.engine.score_fit`) and kept when every contact surface still touches the
surface. A grasp that cannot be settled keeps its planned pose and joints and is marked
unsettled (:attr:`Settled.settled`); the planner ranks it after the settled ones.

The allowance is one noise width for the whole surface; at an object's edge the observation is
worse (:mod:`isf.scene.finger_depth`). Each settled grasp is also told whether its fingers'
local depth bound (depth into the observed surface plus ``NOISE_MARGIN`` local scatter widths,
point by point) is within the collision tolerance (:attr:`Settled.within_bound`); the planner
ranks the settled grasps beyond it after those within it and before the unsettled ones
(measured in docs/benchmark-scenes.md).

Frames: poses are ``T_scene_gripper`` (the planner's ``T_object_gripper`` on a scene), metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from ..collision.checker import CollisionChecker, CollisionReport, Plane
from ..config import FitConfig
from ..fitting.engine import score_fit
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..result import FitResult
from .finger_depth import FingerDepth
from .loading import Scene

__all__ = ["BOUND_STEPS", "NOISE_MARGIN", "SETTLE_STEPS", "STEP_MARGIN", "Settled", "Settler",
           "contact_allowance"]

NOISE_MARGIN = 1.5
"""How many noise widths (``Scene.noise``) the contact allowance takes off the collision
tolerance."""

SETTLE_STEPS = 8
"""Moves (an opening of the fingers or a back-off of the palm) tried per grasp at most."""

STEP_MARGIN = 3e-4
"""Metres a move goes beyond the excess depth it removes (the depth estimate on a noisy surface
does not fall one for one with the move)."""

BOUND_STEPS = 4
"""Moves tried at most to bring a settled grasp's fingers within their local depth bound."""

_MIN_MOVE = 2e-4  # m, the smallest finger opening worth making


def contact_allowance(scene: Scene, tolerance: float) -> float:
    """The penetration a settled grasp may keep against the scene's observed surface, metres:
    ``max(0, tolerance - NOISE_MARGIN * scene.noise)``."""
    return max(0.0, float(tolerance) - NOISE_MARGIN * float(scene.noise))


class Settled(NamedTuple):
    """A grasp after :meth:`Settler.settle`.

    Attributes:
        result: the settled fit (the given one when nothing moved or settling failed).
        report: its collision check at the contact allowance when settled, else the given one.
        settled: True when the grasp is within the contact allowance, every contact surface
            touching; False for a collision-free grasp that could not be settled; None for a
            grasp that collides.
        within_bound: for a settled grasp, True when its fingers' local depth bound
            (:class:`~isf.scene.finger_depth.FingerDepth`) is within the collision tolerance
            (or the scene has no local scatter), else False; None when not settled.
    """

    result: FitResult
    report: CollisionReport
    settled: bool | None
    within_bound: bool | None = None


class Settler:
    """Settles the grasps of one plan on a scene (see the module docstring).

    Args:
        gripper: the gripper planned with.
        obj: the surface planned on (the scene's surface, as the planner thinned it), scene frame.
        scene: the scene (its unseen space, its noise).
        config: the fit parameters (for the re-scoring of a settled state).
        obstacles: the obstacle planes of the plan (the table included), scene frame.
        tolerance: the plan's collision tolerance, metres.

    Attributes:
        allowance: the contact allowance, metres (:func:`contact_allowance`).
        tolerance: the plan's collision tolerance, metres: the largest local depth bound
            (:mod:`isf.scene.finger_depth`) a settled grasp keeps.
        finger_depth: the fingers' local depth bound on the scene's surface, or None for a
            scene without local scatter (``Scene.scatter``).
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, scene: Scene, config: FitConfig, *,
                 obstacles: Sequence[Plane] = (), tolerance: float = 0.002):
        self.gripper, self.obj, self.config = gripper, obj, config
        self.allowance = contact_allowance(scene, tolerance)
        self.tolerance = float(tolerance)
        self.finger_depth = None if scene.scatter is None else FingerDepth(
            gripper, scene.surface.points, scene.surface.normals, scene.scatter, NOISE_MARGIN)
        self.checker = CollisionChecker(gripper, obj, obstacles=obstacles,
                                        tolerance=self.allowance, hidden=scene.unseen)
        self._contact_links = frozenset(gripper.contact_links)
        self._q_open = gripper.q_open
        self._open_points, _ = gripper.contact_points(gripper.q_open)
        self._approach = gripper.approach_root

    def settle(self, result: FitResult, report: CollisionReport) -> Settled:
        """Settle a collision-free grasp (``result`` and its planner's ``report``); a grasp
        that collides comes back unchanged with ``settled`` None."""
        if not report.collision_free:
            return Settled(result, report, None)
        failed = Settled(result, report, False)
        T, q = np.array(result.T_object_gripper, dtype=float), np.array(result.q, dtype=float)
        moved, pressed = False, set()
        check = self.checker.check(T, q)
        for _ in range(SETTLE_STEPS + 1):
            if check.collision_free:
                break
            pressed.update(self._contact_links.intersection(check.colliding_links))
            T, q, check = self._step(T, q, check, pressed)
            moved = True
        else:
            return failed
        if moved:
            result = score_fit(self.gripper, self.obj, T, q, self.config, result.status,
                               result.history, result.time)
            if not result.all_surfaces_in_contact:
                return failed
        if self.finger_depth is None:
            return Settled(result, check, True, True)
        eased = self._ease(T, q, check)
        if eased is None:
            return Settled(result, check, True, False)
        T_eased, q_eased, check_eased = eased
        if T_eased is T and q_eased is q:
            return Settled(result, check, True, True)
        scored = score_fit(self.gripper, self.obj, T_eased, q_eased, self.config, result.status,
                           result.history, result.time)
        if not scored.all_surfaces_in_contact:
            return Settled(result, check, True, False)
        return Settled(scored, check_eased, True, True)

    def _ease(self, T: np.ndarray, q: np.ndarray, check: CollisionReport
              ) -> tuple[np.ndarray, np.ndarray, CollisionReport] | None:
        """A settled state moved until its fingers' local depth bound is within the tolerance
        (the given state when it already is), with its check; None when
        :data:`BOUND_STEPS` moves do not get there while staying within the allowance.

        Each move goes :data:`STEP_MARGIN` beyond the largest excess of a finger's bound over
        the tolerance: the hand against the contact normal of the one finger beyond it, the
        fingers opening, or the hand backing off along its approach, whichever leaves the
        smallest bound."""
        bounds = self.finger_depth.by_finger(T, q)
        for step in range(BOUND_STEPS + 1):
            excess = max(bounds.values(), default=-np.inf) - self.tolerance
            if excess <= 0:
                return T, q, check
            if step == BOUND_STEPS:
                return None
            move = excess + STEP_MARGIN
            over = [k for k, link in enumerate(self.gripper.contact_links)
                    if bounds.get(link, -np.inf) > self.tolerance]
            candidates = [(self._backed_off(T, move), q)]
            opened = self._opened(q, move)
            if opened is not None:
                candidates.append((T, opened))
            if len(over) == 1:
                candidates.append((self._shifted_off(T, q, over[0], move), q))
            best = None
            for T_c, q_c in candidates:
                report = self.checker.check(T_c, q_c)
                if not report.collision_free:
                    continue
                by_finger = self.finger_depth.by_finger(T_c, q_c)
                bound = max(by_finger.values(), default=-np.inf)
                if best is None or bound < best[0]:
                    best = (bound, T_c, q_c, report, by_finger)
            if best is None or best[0] >= excess + self.tolerance:
                return None
            _, T, q, check, bounds = best
        return None

    def _step(self, T: np.ndarray, q: np.ndarray, check: CollisionReport, pressed: set[str]
              ) -> tuple[np.ndarray, np.ndarray, CollisionReport]:
        """One move out of the surface for a state whose ``check`` at the allowance failed
        (``pressed``: the fingers found too deep so far, this state's included): the
        preferred move, or when it goes no less deep the least deep of the others; the moved
        state and its check."""
        move = check.penetration - self.allowance + STEP_MARGIN
        T_preferred, q_preferred = self._preferred(T, q, check, pressed, move)
        report = self.checker.check(T_preferred, q_preferred)
        if report.penetration < check.penetration:
            return T_preferred, q_preferred, report
        candidates = [(_translated(T, sign * move * T[:3, axis]), q) for axis in (0, 1)
                      for sign in (1.0, -1.0)]
        candidates.append((self._backed_off(T, move), q))
        opened = self._opened(q, move)
        if opened is not None:
            candidates.append((T, opened))
        reports = [self.checker.check(*state) for state in candidates]
        best = int(np.argmin([r.penetration for r in reports]))
        return (*candidates[best], reports[best])

    def _preferred(self, T: np.ndarray, q: np.ndarray, check: CollisionReport, pressed: set[str],
                   move: float) -> tuple[np.ndarray, np.ndarray]:
        """The move the module docstring's rules prefer, ``move`` metres."""
        fingers = [k for k, link in enumerate(self.gripper.contact_links)
                   if link in check.colliding_links]
        others = set(check.colliding_links).difference(self.gripper.contact_links)
        if fingers and not others and len(pressed) == 1:  # one finger presses: shift it out
            return self._shifted_off(T, q, fingers[0], move), q
        if not others:
            opened = self._opened(q, move)
            if opened is not None:
                return T, opened
        return self._backed_off(T, move), q

    def _shifted_off(self, T: np.ndarray, q: np.ndarray, finger: int, move: float) -> np.ndarray:
        """``T`` moved ``move`` metres against the mean contact normal of finger ``finger`` (an
        index of ``Gripper.contact_links``) at joints ``q``: that finger out of the surface."""
        _, normals = self.gripper.contact_points(q)
        n = normals[self.gripper.point_link == finger].mean(axis=0)
        return _translated(T, -move * (T[:3, :3] @ (n / np.linalg.norm(n))))

    def _backed_off(self, T: np.ndarray, move: float) -> np.ndarray:
        """``T`` moved ``move`` metres back along the gripper's approach direction."""
        return _translated(T, -move * (T[:3, :3] @ self._approach))

    def _opened(self, q: np.ndarray, move: float) -> np.ndarray | None:
        """``q`` with the fingers opened so the contact points move by ``move`` metres at most
        (along the segment to :attr:`isf.Gripper.q_open`), or None when they are already open."""
        start, _ = self.gripper.contact_points(q)
        reach = float(np.linalg.norm(self._open_points - start, axis=1).max())
        if reach < _MIN_MOVE:
            return None
        return q + min(1.0, move / reach) * (self._q_open - q)


def _translated(T: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``T`` (4, 4) moved by ``shift`` (3,) metres in the scene frame."""
    out = T.copy()
    out[:3, 3] += shift
    return out
