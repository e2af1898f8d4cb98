"""The MuJoCo model of one grasp: the gripper fixed in space and the object free.

Frames
------
``world``
    MuJoCo's world frame is the plan's object frame at the start: the object body starts at
    the identity, the gripper's root link is fixed at ``T_object_gripper``.

The gripper is built from its URDF (read with yourdfpy): one body per link, a hinge or slide
joint per revolute or prismatic URDF joint (fixed joints weld the child to its parent), a
MuJoCo joint-equality constraint ``q_mimic = multiplier * q_leader + offset`` for each
``<mimic>`` joint (stiff: the follower does not yield under the grip), and a position
actuator on each actuated joint with its force bounded. Each link's collision elements
(``Gripper.geometries``) become mesh geoms: one per convex part
(``isf.simulation.object_body.convex_parts``: a box stays one, a grooved fingertip or a
curved pad surface is split by CoACD, so that its hull does not fill the groove). Gripper
links have nominal inertia and gravity compensation: their own weight does not load the
actuators. Only gripper-object pairs collide.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..exceptions import InvalidInputError
from ..gripper.model import Gripper
from ..gripper.yourdfpy_reading import read_urdf
from .object_body import ObjectBody, convex_parts
from .settings import SimulationSettings

__all__ = ["GraspWorld", "build_world", "force_bounds", "physics_spec"]

#: Nominal mass (kg) and inertia (kg m^2) of each gripper link: the links are position-driven.
LINK_MASS, LINK_INERTIA = 0.05, 1e-5
#: Error at which a position actuator reaches its force bound: metres (prismatic), rad (revolute).
FULL_FORCE_ERROR = {False: 0.002, True: 0.02}
#: Joint armature (kg or kg m^2) and damping (N s/m or N m s/rad), prismatic / revolute.
ARMATURE = {False: 0.01, True: 1e-3}
DAMPING = {False: 2.0, True: 0.02}
#: Time constant of the ``<mimic>`` joint equalities, in integration steps: MuJoCo's stiffest
#: stable setting (its default 0.02 s lets a follower finger yield millimetres under the grip, so
#: that part of the actuator's force never reaches the object).
MIMIC_TIMECONST_STEPS = 2
GRIPPER_BITS, OBJECT_BITS = 1, 2
OBJECT_BODY = "isf_object"


class GraspWorld(NamedTuple):
    """A compiled grasp world.

    Attributes:
        model: the ``mujoco.MjModel``.
        actuated: the gripper's actuated joints (``Gripper.joint_names`` order),
            one position actuator each in that order.
        qpos_index: address in ``qpos`` of each actuated joint, (n_joints,).
        mimic_qpos: (address, leader index into ``actuated``, multiplier, offset) per mimic joint.
        object_body: MuJoCo body id of the object.
        object_qpos: address of the object's free joint in ``qpos`` (position, then quaternion).
        gripper_geoms: geom ids of the gripper, (G,).
        object_geoms: geom ids of the object, (P,).
    """

    model: Any
    actuated: tuple[str, ...]
    qpos_index: np.ndarray
    mimic_qpos: tuple[tuple[int, int, float, float], ...]
    object_body: int
    object_qpos: int
    gripper_geoms: np.ndarray
    object_geoms: np.ndarray


def _quat(R: np.ndarray) -> list[float]:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return q.tolist()


def _urdf(gripper: Gripper):
    if gripper.urdf_path is None:
        raise InvalidInputError(f"gripper {gripper.name!r} has no URDF file: load it with "
                                "isf.load_gripper to simulate it")
    return read_urdf(gripper.urdf_path, load_meshes=False, build_scene_graph=False,
                     build_collision_scene_graph=False).robot


def _add_mesh_geom(spec, body, name: str, vertices: np.ndarray, faces: np.ndarray,
                   friction: float, bits: tuple[int, int]) -> bool:
    """A mesh geom (MuJoCo collides its convex hull); False when the points span no volume."""
    centred = vertices - vertices.mean(axis=0)
    if len(vertices) < 4 or np.linalg.matrix_rank(centred, tol=1e-6) < 3:
        return False
    mesh = spec.add_mesh(name=name)
    mesh.uservert = np.asarray(vertices, dtype=np.float32).ravel().tolist()
    mesh.userface = np.asarray(faces, dtype=np.int32).ravel().tolist()
    import mujoco

    geom = body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name)
    geom.friction = [friction, 0.0, 0.0]
    geom.condim = 3
    geom.contype, geom.conaffinity = bits
    geom.mass = 0.0
    return True


def physics_spec(settings: SimulationSettings):
    """An empty ``mujoco.MjSpec`` with the solver options of every grasp world: gravity off,
    elliptic friction cones with ``impratio`` 10 (contacts that stick do not creep), the
    implicit-fast integrator, 5 no-slip iterations, ``settings.timestep``, and multi-point
    convex collisions (``multiccd``: a pad on a face touches at the corners of their overlap,
    so the patch resists a torque about its normal and a tilt; one point would not); angles in
    radians."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.option.timestep = settings.timestep
    spec.option.gravity = [0.0, 0.0, 0.0]
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.noslip_iterations = 5
    if hasattr(mujoco.mjtDisableBit, "mjDSBL_MULTICCD"):  # MuJoCo 4: on unless disabled
        spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_MULTICCD)
    else:  # MuJoCo 3: off unless enabled
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_MULTICCD)
    spec.compiler.autolimits = True
    spec.compiler.degree = False  # joint ranges in radians, as URDF states them (MuJoCo reads degrees)
    return spec


def force_bounds(gripper: Gripper, q: np.ndarray, finger_force: float) -> np.ndarray:
    """Each actuated joint's force (N) or torque (N m) bound, (n_joints,), such that every
    contact surface the joint moves can press with ``finger_force`` newtons.

    By virtual work a joint's generalised force is the sum, over the contact surfaces it moves,
    of their normal force times their speed per unit of joint motion (metres per metre of a
    prismatic joint, the lever arm in metres per radian of a revolute one; the mean over the
    surface's moving points, from the contact Jacobians at ``q``). A joint whose ``<mimic>``
    followers move the opposite jaw of a parallel gripper therefore gets twice ``finger_force``:
    each jaw presses with ``finger_force``, as the URDF's per-joint ``effort`` states for both.
    """
    speed = np.linalg.norm(gripper.contact_kinematics(q).J_points, axis=1)  # (M, n_joints)
    bounds = np.zeros(gripper.n_joints)
    for surface in range(len(gripper.surfaces)):
        on_surface = speed[gripper.point_surface == surface]  # (M_s, n_joints)
        moving = on_surface > 1e-9
        count = moving.sum(axis=0)
        mean = np.where(count > 0, (on_surface * moving).sum(axis=0) / np.maximum(count, 1), 0.0)
        bounds += finger_force * mean
    unmoved = bounds <= 0.0  # a joint that moves no contact point: a nominal 5 cm lever
    bounds[unmoved] = finger_force * np.where(gripper.revolute[unmoved], 0.05, 1.0)
    return bounds


def build_world(gripper: Gripper, body: ObjectBody, T_object_gripper: np.ndarray,
                q: np.ndarray, settings: SimulationSettings) -> GraspWorld:
    """Compile the MuJoCo model of ``gripper`` at ``T_object_gripper`` (4, 4) around ``body``,
    with actuator bounds computed at the planned joints ``q`` (n_joints,)."""
    import mujoco

    robot = _urdf(gripper)
    spec = physics_spec(settings)

    children: dict[str, list] = {}
    for joint in robot.joints:
        children.setdefault(joint.parent, []).append(joint)
    child_links = {j.child for j in robot.joints}
    roots = [link.name for link in robot.links if link.name not in child_links]
    if len(roots) != 1:
        raise InvalidInputError(f"gripper {gripper.name!r} has {len(roots)} root links; one expected")
    geoms_of: dict[str, list] = {}
    for g in gripper.geometries:
        geoms_of.setdefault(g.link, []).append(g)

    T = np.asarray(T_object_gripper, dtype=float)
    root = spec.worldbody.add_body(name=roots[0], pos=T[:3, 3].tolist(), quat=_quat(T[:3, :3]))
    mimics: list[tuple[str, str, float, float]] = []

    def add_link(mj_body, link: str, is_root: bool) -> None:
        if not is_root:
            mj_body.explicitinertial = True
            mj_body.mass = LINK_MASS
            mj_body.inertia = [LINK_INERTIA] * 3
            mj_body.gravcomp = 1.0
        for k, g in enumerate(geoms_of.get(link, [])):
            for j, (v, f) in enumerate(convex_parts(g.vertices, g.faces, settings.part_tolerance)):
                _add_mesh_geom(spec, mj_body, f"g:{link}:{k}:{j}", v, f, settings.friction,
                               (GRIPPER_BITS, OBJECT_BITS))
        for joint in children.get(link, []):
            origin = np.asarray(joint.origin if joint.origin is not None else np.eye(4), dtype=float)
            child = mj_body.add_body(name=joint.child, pos=origin[:3, 3].tolist(),
                                     quat=_quat(origin[:3, :3]))
            if joint.type in ("revolute", "continuous", "prismatic"):
                kind = mujoco.mjtJoint.mjJNT_SLIDE if joint.type == "prismatic" else mujoco.mjtJoint.mjJNT_HINGE
                axis = joint.axis if joint.axis is not None else np.array([1.0, 0.0, 0.0])
                mj_joint = child.add_joint(name=joint.name, type=kind, axis=list(map(float, axis)))
                mj_joint.damping = [DAMPING[joint.type != "prismatic"], 0.0, 0.0]
                mj_joint.armature = ARMATURE[joint.type != "prismatic"]
                lim = joint.limit
                if joint.type != "continuous" and lim is not None and lim.lower is not None \
                        and lim.upper is not None:
                    mj_joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
                    mj_joint.range = [float(lim.lower), float(lim.upper)]
                if joint.mimic is not None:
                    mimics.append((joint.name, joint.mimic.joint, float(joint.mimic.multiplier or 1.0),
                                   float(joint.mimic.offset or 0.0)))
            elif joint.type != "fixed":
                raise InvalidInputError(f"joint {joint.name!r} of type {joint.type!r} cannot be "
                                        "simulated (revolute, continuous, prismatic, fixed only)")
            add_link(child, joint.child, False)

    add_link(root, roots[0], True)

    obj = spec.worldbody.add_body(name=OBJECT_BODY)
    obj.add_freejoint(name=OBJECT_BODY)
    obj.explicitinertial = True
    obj.mass = body.mass
    obj.ipos = body.center_of_mass.tolist()
    I = body.inertia
    obj.fullinertia = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    for k, (v, f) in enumerate(body.parts):
        _add_mesh_geom(spec, obj, f"o:{k}", v, f, settings.friction, (OBJECT_BITS, GRIPPER_BITS))

    for name, leader, multiplier, offset in mimics:
        eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=name, name2=leader)
        eq.data[:5] = [offset, multiplier, 0.0, 0.0, 0.0]
        eq.solref = [MIMIC_TIMECONST_STEPS * settings.timestep, 1.0]
    actuated = gripper.joint_names
    bounds = force_bounds(gripper, q, settings.finger_force)
    for j, name in enumerate(actuated):
        if spec.joint(name) is None:
            raise InvalidInputError(f"joint {name!r} of gripper {gripper.name!r} is not in its URDF")
        force = float(bounds[j])
        act = spec.add_actuator(name=f"a:{name}", target=name,
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=force / FULL_FORCE_ERROR[bool(gripper.revolute[j])], dampratio=1.0)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-force, force]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    model = spec.compile()

    def qadr(name: str) -> int:
        return int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)])

    mimic_qpos = tuple((qadr(n), actuated.index(lead), m, o) for n, lead, m, o in mimics
                       if lead in actuated)
    obj_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_BODY)
    geom_body = np.asarray(model.geom_bodyid)
    return GraspWorld(model=model, actuated=actuated,
                      qpos_index=np.array([qadr(n) for n in actuated], dtype=np.int64),
                      mimic_qpos=mimic_qpos, object_body=obj_id, object_qpos=qadr(OBJECT_BODY),
                      gripper_geoms=np.flatnonzero(geom_body != obj_id),
                      object_geoms=np.flatnonzero(geom_body == obj_id))
