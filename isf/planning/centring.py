"""Centring: a valid grasp slid toward the object's centre of mass along the directions its fit
leaves free.

ISF matches contact surfaces to the object and stops where the matches stop improving. A flat pad
on a flat face fits equally well anywhere on the face, so a fit stays wherever its start put it:
often at a rim, far from the centre of mass, where a grip of bounded force cannot stop the
object's weight from turning it about the contacts (``docs/validate.md`` measures how often that
happens in physics). :class:`GraspCentring` moves each valid grasp (collision-free, every contact
surface touching), its joints fixed unless they must re-close:

1. **Free directions.** With the contact normals ``n_i`` of every contact point (object frame),
   a translation ``t`` of the gripper changes the point-to-plane distances by ``n_i . t``; the
   eigenvectors of ``M = mean(n_i n_i^T)`` whose eigenvalue is below
   :attr:`isf.CentringConfig.free_ratio` times the largest are directions the fit is (nearly)
   indifferent to: the plane of a parallel gripper's pads, the axis of a can between them.
2. **The move.** The offset from the contact centre (the mean of the contact surfaces'
   centres) to the centre of mass (:func:`isf.quality.grasp_quality.object_properties`),
   projected on the free directions; tried at each of :attr:`isf.CentringConfig.fractions` of its
   length, then along each free direction alone at the same fractions (a move that leaves a
   curved face one way may keep it the other).
3. **The check.** The first move whose state the plan's collision check finds collision-free,
   whose every contact surface still touches with at least :attr:`isf.CentringConfig.contact_keep`
   of the fit's smallest contact fraction, and whose mean point-to-plane distance (rescored:
   :func:`isf.fitting.engine.score_fit`) exceeds the fit's by at most
   :attr:`isf.CentringConfig.error_slack` is kept; the collision check bounds how deep the palm goes.
   Moves shorter than :attr:`isf.CentringConfig.min_move` are not tried.
4. **Re-closing.** A move that fails the check with the fit's joints is tried again with the
   joints re-closed onto the object at the moved pose
   (:func:`isf.fitting.reclosing.reclose_joints`, starting from the joints the longer move
   before it re-closed to): an object whose width changes along its face (a bulged carton, a
   tapered bottle) leaves the contact surfaces off it, or pressed into it, where it is thinner
   or wider than at the fit. When no move passes either way, the grasp stays as fitted.

The planner centres the grasps of plans on objects (:func:`isf.plan`'s ``centring``); a scene
has no one centre of mass (the cloud is unsegmented and partial), so its grasps are not centred.

Frames: poses are ``T_object_gripper`` (gripper root link in the object frame), metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..collision.checker import CollisionChecker, CollisionReport
from ..config import FitConfig, check_field
from ..exceptions import ConfigError
from ..fitting.engine import PoseScorer, score_fit
from ..fitting.reclosing import reclose_joints
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..result import FitResult, FitStatus

__all__ = ["Centred", "CentringConfig", "GraspCentring", "free_directions"]


@dataclass(frozen=True, kw_only=True)
class CentringConfig:
    """Parameters of the centring of :func:`isf.plan` (``centring=``), the slide of each valid
    grasp toward the centre of mass (:mod:`isf.planning.centring`), SI units.

    Attributes:
        fractions: fractions of the move to the centre of mass tried, in order (each in
            (0, 1]; the first that passes the check is kept).
        free_ratio: a direction is free when its eigenvalue of the contact normals' matrix is
            below this times the largest.
        error_slack: how much the mean point-to-plane distance may grow, metres.
        contact_keep: each contact surface keeps at least this fraction of the fit's smallest
            contact fraction (the share of a surface's points within ``contact_distance``).
        min_move: shorter moves are not tried, metres.
        reclose: try a move that fails with the fit's joints again with the joints re-closed
            onto the object (:func:`isf.fitting.reclosing.reclose_joints`); False keeps the
            joints fixed.
    """

    fractions: tuple[float, ...] = (1.0, 0.75, 0.5, 0.25)
    free_ratio: float = 0.1
    error_slack: float = 0.0005
    contact_keep: float = 0.7
    min_move: float = 0.002
    reclose: bool = True

    def __post_init__(self) -> None:
        """Refuse values of the wrong type or out of range (:class:`ConfigError`)."""
        fractions = tuple(self.fractions) if isinstance(self.fractions, (tuple, list)) else None
        if not fractions:
            raise ConfigError("CentringConfig.fractions must be a non-empty tuple of numbers in "
                              f"(0, 1], got {self.fractions!r}")
        for value in fractions:
            check_field("CentringConfig", "fractions", value, above=0.0, high=1.0)
        object.__setattr__(self, "fractions", tuple(float(f) for f in fractions))
        check_field("CentringConfig", "free_ratio", self.free_ratio, above=0.0, high=1.0)
        check_field("CentringConfig", "error_slack", self.error_slack, low=0.0)
        check_field("CentringConfig", "contact_keep", self.contact_keep, low=0.0, high=1.0)
        check_field("CentringConfig", "min_move", self.min_move, above=0.0)
        if not isinstance(self.reclose, bool):
            raise ConfigError(f"CentringConfig.reclose must be True or False, got {self.reclose!r}")


class Centred(NamedTuple):
    """A grasp after :meth:`GraspCentring.centre`: its fit and collision report (the slid
    state's when it moved), and how far it moved, metres (0 when it stayed)."""

    result: FitResult
    report: CollisionReport
    shift: float


def free_directions(normals: np.ndarray, free_ratio: float) -> np.ndarray:
    """Unit directions along which a translation leaves the point-to-plane distances of contacts
    with these ``normals`` (K, 3) nearly unchanged: the eigenvectors of ``mean(n n^T)`` whose
    eigenvalue is below ``free_ratio`` times the largest, as columns (3, F), F from 0 to 3."""
    normals = np.asarray(normals, dtype=float)
    if len(normals) == 0:
        return np.eye(3)
    values, vectors = np.linalg.eigh(normals.T @ normals / len(normals))
    return vectors[:, values < free_ratio * values.max()]


class GraspCentring:
    """Slides the valid grasps of one plan toward the centre of mass (see the module docstring).

    Args:
        gripper: the gripper planned with.
        obj: the surface planned on, object frame.
        center_of_mass: the object's centre of mass, object frame, (3,), metres.
        checker: the plan's collision check (its obstacles and tolerance).
        fit_config: the fit parameters (for the rescoring of a slid state).
        config: the centring parameters; default ``isf.CentringConfig()``.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, center_of_mass: np.ndarray,
                 checker: CollisionChecker, fit_config: FitConfig,
                 config: CentringConfig | None = None):
        self.gripper, self.obj, self.checker, self.fit_config = gripper, obj, checker, fit_config
        self.center_of_mass = np.asarray(center_of_mass, dtype=float).reshape(3)
        self.config = CentringConfig() if config is None else config

    def centre(self, result: FitResult, report: CollisionReport) -> Centred:
        """The grasp ``result`` (with its collision ``report``) slid toward the centre of mass,
        or as it is when it is not valid or no move passes the check."""
        stays = Centred(result, report, 0.0)
        if not (report.collision_free and result.status is not FitStatus.LOST_CONTACT
                and result.all_surfaces_in_contact):
            return stays
        config = self.config
        T, q = np.asarray(result.T_object_gripper, dtype=float), np.asarray(result.q, dtype=float)
        points, normals = self.gripper.contact_points(q)
        R = T[:3, :3]
        points = points @ R.T + T[:3, 3]
        surface = self.gripper.point_surface
        centre = np.mean([points[surface == k].mean(axis=0)
                          for k in range(len(self.gripper.surfaces))], axis=0)
        free = free_directions(normals @ R.T, config.free_ratio)
        offset = free.T @ (self.center_of_mass - centre)  # (F,), along each free direction
        # whole moves: toward the centre of mass, then along each free direction alone
        wholes = [free @ offset]
        if free.shape[1] > 1:
            wholes += [offset[k] * free[:, k] for k in range(free.shape[1])]
        least_contact = config.contact_keep * min(result.surface_contact.values())
        most_distance = result.mean_distance + config.error_slack

        def passes(scorer: PoseScorer, pose: np.ndarray) -> bool:
            scored = scorer(pose)  # a rescoring: a tenth of a collision check's cost
            return (scored.surface_contact.min() > 0.0
                    and scored.surface_contact.min() >= least_contact
                    and scored.mean_distance <= most_distance)

        score = None
        for whole in wholes:
            guess = q  # where the next re-closing starts: the joints the last one found
            for fraction in config.fractions:
                move = fraction * whole
                shift = float(np.linalg.norm(move))
                if shift < config.min_move:
                    continue
                moved = T.copy()
                moved[:3, 3] += move
                score = score or PoseScorer(self.gripper, self.obj, self.fit_config, q)
                if passes(score, moved):
                    slid = self._checked(result, moved, q, shift)
                    if slid is not None:
                        return slid
                if config.reclose:
                    guess = reclose_joints(self.gripper, self.obj, moved, guess)
                    if np.array_equal(guess, q):  # the state just tried with the fit's joints
                        continue
                    if passes(PoseScorer(self.gripper, self.obj, self.fit_config, guess), moved):
                        slid = self._checked(result, moved, guess, shift)
                        if slid is not None:
                            return slid
        return stays

    def _checked(self, result: FitResult, T: np.ndarray, q: np.ndarray,
                 shift: float) -> Centred | None:
        """The slid state ``(T, q)`` of ``result`` when the plan's collision check passes it,
        else None."""
        check = self.checker.check(T, q)
        if not check.collision_free:
            return None
        return Centred(score_fit(self.gripper, self.obj, T, q, self.fit_config, result.status,
                                 result.history, result.time), check, shift)
