"""The parameters of the physics test of a grasp (:func:`isf.simulation.validate_grasp`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from ..exceptions import InvalidInputError

__all__ = ["SimulationSettings"]


@dataclass(frozen=True)
class SimulationSettings:
    """How a grasp is tested in MuJoCo (SI units; see docs/validate.md).

    Attributes:
        friction: Coulomb friction coefficient of every gripper-object contact.
        mass: object mass, kg (spread uniformly over the mesh's volume).
        finger_force: the normal force each contact surface can press with, N: each
            actuator's bound is this times the speed of every contact surface the joint moves
            (1 per surface for a prismatic jaw; a revolute joint's lever arm), so both jaws of
            a parallel gripper whose second jaw is a ``<mimic>`` squeeze with it (the URDF's
            ``effort`` is not used: hand-made URDFs rarely state a real one).
        open_prismatic: how far a prismatic finger starts open of its planned value, m.
        open_revolute: how far a revolute finger starts open of its planned value, rad.
        squeeze_prismatic: how far past the planned value the actuator's target lies, m.
        squeeze_revolute: the same for revolute joints, rad.
        penetration_limit: gripper-object penetration at the planned joints above which the
            grasp is ``penetrating`` and not simulated, m.
        part_tolerance: how far the convex parts MuJoCo collides may stand off the object's and
            the gripper's meshes, m (:func:`isf.simulation.object_body.convex_parts`): smaller
            is more faithful, with more parts, slower to make and to simulate.
        eject_distance: object displacement during closing above which it is ``ejected``, m.
        slip_distance: object displacement while held against gravity above which it ``slipped``, m.
        slip_angle: object rotation while held above which it ``slipped``, rad.
        close_time: simulated closing time (gravity off), s.
        hold_time: simulated time held against gravity in each direction, s.
        gravity: magnitude of gravity in the hold phase, m/s^2.
        timestep: the integration step, s.
    """

    friction: float = 0.5
    mass: float = 0.3
    finger_force: float = 20.0
    open_prismatic: float = 0.01
    open_revolute: float = 0.2
    squeeze_prismatic: float = 0.005
    squeeze_revolute: float = 0.1
    penetration_limit: float = 0.003
    part_tolerance: float = 0.001
    eject_distance: float = 0.05
    slip_distance: float = 0.01
    slip_angle: float = 0.2
    close_time: float = 0.6
    hold_time: float = 1.0
    gravity: float = 9.81
    timestep: float = 0.001

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if value is not None and not value >= 0.0:
                raise InvalidInputError(f"simulation setting {name}={value} must be >= 0")
        if self.mass <= 0.0 or self.timestep <= 0.0 or self.part_tolerance <= 0.0:
            raise InvalidInputError("simulation mass, timestep and part_tolerance must be > 0")

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict."""
        return asdict(self)

    @classmethod
    def for_plan(cls, plan: dict, **given) -> SimulationSettings:
        """The settings to test the grasps of ``plan`` (a plan file's dict) with: the friction
        and mass the plan was ranked with (its ``ranking.quality``; the defaults for a plan
        ranked by fit), and any setting in ``given`` that is not None."""
        ranked = (plan.get("ranking") or {}).get("quality") or {}
        fields = {name: ranked[name] for name in ("friction", "mass") if name in ranked}
        fields.update({name: value for name, value in given.items() if value is not None})
        return cls(**fields)
