"""The physics test of one grasp: close the fingers, then hold against gravity in six directions.

1. **Penetration.** At the planned joints, the deepest gripper-object contact (MuJoCo's convex
   geometry) above ``penetration_limit`` makes the grasp ``penetrating``; it is not simulated.
2. **Closing** (gravity off). The fingers start ``open_*`` away from the planned joints, against
   their closing direction (``Gripper.closing``, or
   ``Gripper.suggested_closing`` for joints not declared; a joint of sign 0 stays at its
   planned value), and position actuators with
   bounded force follow targets moving at constant speed, over ``CLOSING_RAMP`` of
   ``close_time``, to ``squeeze_*`` past the planned joints, and hold them there. The
   object is ``ejected`` if it moved more than ``eject_distance`` or touches no gripper geom.
3. **Hold.** From the closed state, the gripper stays fixed in space while gravity points along
   +x, -x, +y, -y, +z and -z of the world (the object frame) in turn, ``hold_time`` each. The
   object ``slipped`` in a direction if it moved more than ``slip_distance`` or turned more than
   ``slip_angle`` from its closed pose; otherwise it ``held``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..gripper.model import Gripper
from .dependencies import require_simulator
from .object_body import ObjectBody
from .settings import SimulationSettings
from .world import GraspWorld, build_world

__all__ = ["DIRECTIONS", "DirectionResult", "GraspValidation", "Outcome", "close_fingers",
           "set_joints", "validate_grasp"]

#: Gravity directions of the hold phase, in the world (object) frame.
DIRECTIONS: dict[str, tuple[float, float, float]] = {
    "+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0), "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0), "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0)}


#: Fraction of the closing time over which the actuator targets move from open to closed.
CLOSING_RAMP = 0.7


class Outcome(str, Enum):
    """What happened to the object."""

    HELD = "held"
    SLIPPED = "slipped"
    EJECTED = "ejected"
    PENETRATING = "penetrating"


@dataclass(frozen=True)
class DirectionResult:
    """The hold against gravity along one direction.

    Attributes:
        direction: a key of ``DIRECTIONS``.
        outcome: held or slipped (or the grasp's ejected / penetrating).
        displacement: the object's centre-of-mass displacement from its closed pose, m.
        rotation: its rotation from its closed pose, rad.
    """

    direction: str
    outcome: Outcome
    displacement: float
    rotation: float


@dataclass(frozen=True)
class GraspValidation:
    """The physics test of one grasp.

    Attributes:
        outcome: ``held`` when every direction held; ``slipped`` when one or more slipped;
            ``ejected`` or ``penetrating`` when the hold phase did not run.
        directions: one :class:`DirectionResult` per direction (empty when not simulated).
        penetration: deepest gripper-object penetration at the planned joints, m.
        closing_displacement: the object's displacement during closing, m (0 when not simulated).
    """

    outcome: Outcome
    directions: tuple[DirectionResult, ...]
    penetration: float
    closing_displacement: float

    @property
    def held_directions(self) -> int:
        """How many directions held."""
        return sum(d.outcome is Outcome.HELD for d in self.directions)

    def to_dict(self) -> dict:
        """The JSON form (``validation`` of a grasp in the plan file)."""
        return {"outcome": self.outcome.value, "held_directions": self.held_directions,
                "penetration": self.penetration, "closing_displacement": self.closing_displacement,
                "directions": {d.direction: {"outcome": d.outcome.value,
                                             "displacement": d.displacement,
                                             "rotation": d.rotation} for d in self.directions}}


def set_joints(world: GraspWorld, qpos: np.ndarray, q: np.ndarray) -> None:
    """Writes the actuated joints ``q`` (n_joints,) and their ``<mimic>`` followers into MuJoCo's
    ``qpos``."""
    qpos[world.qpos_index] = q
    for adr, leader, multiplier, offset in world.mimic_qpos:
        qpos[adr] = multiplier * q[leader] + offset


def _object_pose(world: GraspWorld, data) -> tuple[np.ndarray, np.ndarray]:
    return data.xipos[world.object_body].copy(), data.xquat[world.object_body].copy()


def _angle(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(2.0 * np.arccos(min(1.0, abs(float(np.dot(q1, q2))))))


def _contacts(world: GraspWorld, data) -> np.ndarray:
    """Signed distances of the gripper-object contacts, (C,), m (negative: penetrating)."""
    n = data.ncon
    if n == 0:
        return np.zeros(0)
    g1, g2 = data.contact.geom1[:n], data.contact.geom2[:n]
    is_obj1, is_obj2 = np.isin(g1, world.object_geoms), np.isin(g2, world.object_geoms)
    pair = is_obj1 != is_obj2
    return np.asarray(data.contact.dist[:n])[pair]


def close_fingers(gripper: Gripper, world: GraspWorld, data, q: np.ndarray,
                  settings: SimulationSettings) -> np.ndarray:
    """The closing of the test (step 2 of the module docstring) from a reset ``data``: the
    fingers start ``open_*`` from the planned joints ``q`` (n_joints,) against their closing
    signs (:meth:`isf.Gripper.closing_signs`), the actuators' targets move to ``squeeze_*``
    past them over ``CLOSING_RAMP`` of ``close_time`` and hold, gravity as the model has it.
    Returns the object's centre of mass before the closing, (3,), m (world frame)."""
    import mujoco

    model = world.model
    signs = gripper.closing_signs(q)
    opening = np.where(gripper.revolute, settings.open_revolute, settings.open_prismatic)
    squeeze = np.where(gripper.revolute, settings.squeeze_revolute, settings.squeeze_prismatic)
    mujoco.mj_resetData(model, data)
    q_start = np.clip(q - signs * opening, gripper.lower, gripper.upper)
    q_goal = q + signs * squeeze
    set_joints(world, data.qpos, q_start)
    mujoco.mj_forward(model, data)
    start, _ = _object_pose(world, data)
    steps = int(round(settings.close_time / settings.timestep))
    ramp = max(1, int(CLOSING_RAMP * steps))
    for k in range(steps):
        data.ctrl[:] = q_start + min(1.0, (k + 1) / ramp) * (q_goal - q_start)
        mujoco.mj_step(model, data)
    return start


def validate_grasp(gripper: Gripper, body: ObjectBody, T_object_gripper: np.ndarray,
                   q: np.ndarray, settings: SimulationSettings | None = None) -> GraspValidation:
    """Simulate one grasp (see the module docstring).

    Args:
        gripper: the gripper (loaded from its URDF).
        body: the object (:func:`isf.simulation.object_body`), object frame.
        T_object_gripper: the planned gripper pose, (4, 4).
        q: the planned actuated joints, (n_joints,), metres or radians.
        settings: the test's parameters; default :class:`SimulationSettings`.
    """
    require_simulator()
    import mujoco

    settings = settings or SimulationSettings()
    world = build_world(gripper, body, T_object_gripper, np.asarray(q, dtype=float), settings)
    model = world.model
    data = mujoco.MjData(model)
    q = np.asarray(q, dtype=float)

    set_joints(world, data.qpos, q)
    mujoco.mj_forward(model, data)
    dists = _contacts(world, data)
    penetration = float(max(0.0, -dists.min())) if len(dists) else 0.0
    if penetration > settings.penetration_limit:
        return GraspValidation(Outcome.PENETRATING, (), penetration, 0.0)

    start = close_fingers(gripper, world, data, q, settings)
    closed_pos, closed_quat = _object_pose(world, data)
    moved = float(np.linalg.norm(closed_pos - start))
    if moved > settings.eject_distance or len(_contacts(world, data)) == 0:
        return GraspValidation(Outcome.EJECTED, (), penetration, moved)

    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    closed = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, closed, spec)
    results = []
    for key, direction in DIRECTIONS.items():
        mujoco.mj_setState(model, data, closed, spec)
        model.opt.gravity[:] = settings.gravity * np.asarray(direction)
        for _ in range(int(round(settings.hold_time / settings.timestep))):
            mujoco.mj_step(model, data)
        pos, quat = _object_pose(world, data)
        shift, turn = float(np.linalg.norm(pos - closed_pos)), _angle(quat, closed_quat)
        held = shift <= settings.slip_distance and turn <= settings.slip_angle
        results.append(DirectionResult(key, Outcome.HELD if held else Outcome.SLIPPED, shift, turn))
    model.opt.gravity[:] = 0.0
    outcome = Outcome.HELD if all(r.outcome is Outcome.HELD for r in results) else Outcome.SLIPPED
    return GraspValidation(outcome, tuple(results), penetration, moved)
