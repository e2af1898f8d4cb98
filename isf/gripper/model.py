"""The :class:`Gripper`: finger kinematics and contact surfaces of one URDF.

Frames
------
``gripper``
    The URDF's root link. Every pose a user sees, ``T_object_gripper``, places
    this frame in the object frame. Contact points, normals and Jacobians
    returned here are expressed in it.
``<link>``
    Each URDF link's own frame; contact surfaces are stored in their link's frame.
``tcp``
    The tool-centre point a robot controller moves (:attr:`Gripper.T_root_tcp`): declared by
    ``<isf:gripper tcp_link tcp_origin>``, else the centre of the contact surfaces at the
    initial configuration with the root link's axes.

Joint vector ``q``
    One value per *actuated* joint (mimic joints follow their leader and have
    no entry), in the order of :attr:`Gripper.joint_names`; metres for
    prismatic joints, radians for revolute ones.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .chain import KinematicChain

__all__ = ["ContactKinematics", "ContactSurface", "Gripper", "LinkGeometry", "LinkKinematics"]


CLOSING_HOLD_COSINE = 0.2
"""A joint whose contact points move this close to across their outward normals (the mean
cosine between their motion and their normals, weighted by speed, below it: more than 78
degrees off) holds its value while the fingers close: :meth:`Gripper.suggested_closing` gives it
the sign 0 (an abduction joint that swings a fingertip sideways)."""


@dataclass(frozen=True, eq=False)
class ContactSurface:
    """A tagged contact surface, sampled as points with outward normals.

    Attributes:
        name: the ``name`` of its ``<isf:contact>`` tag.
        link: the link that carries it.
        points: surface points in the link frame, shape (N, 3), metres, in
            farthest-point order (every prefix covers the patch evenly).
        normals: unit outward normals in the link frame, shape (N, 3).
        area: area of the selected faces, m^2.
    """

    name: str
    link: str
    points: np.ndarray
    normals: np.ndarray
    area: float


@dataclass(frozen=True, eq=False)
class LinkGeometry:
    """One collision (or visual) geometry of a link as a triangle mesh.

    Attributes:
        link: the link that carries it.
        name: the URDF element's name, or ``<link>_<k>`` for the k-th element.
        vertices: vertex positions in the link frame, shape (V, 3), metres
            (the element's ``<origin>`` and ``<mesh scale>`` applied).
        faces: triangle vertex indices, shape (F, 3).
    """

    link: str
    name: str
    vertices: np.ndarray
    faces: np.ndarray


class ContactKinematics(NamedTuple):
    """Contact points at one joint configuration, in the gripper frame.

    Attributes:
        points: contact points, shape (M, 3), metres.
        normals: unit outward normals, shape (M, 3).
        J_points: point Jacobians d(points)/dq, shape (M, 3, n_joints).
        J_rotation: angular Jacobians of each point's link, shape (M, 3, n_joints):
            d(normals)/dq . dq = (J_rotation . dq) x normals.
    """

    points: np.ndarray
    normals: np.ndarray
    J_points: np.ndarray
    J_rotation: np.ndarray


class LinkKinematics(NamedTuple):
    """Poses and Jacobians of the links that carry contact surfaces, gripper frame.

    Index ``k`` is the link of :attr:`Gripper.contact_links` ``[k]``.

    Attributes:
        rotations: ``R_gripper_link``, shape (L, 3, 3).
        positions: link origins, shape (L, 3), metres.
        J_linear: Jacobians of the link origins, shape (L, 3, n_joints).
        J_angular: angular Jacobians of the links, shape (L, 3, n_joints).
    """

    rotations: np.ndarray
    positions: np.ndarray
    J_linear: np.ndarray
    J_angular: np.ndarray


@dataclass(eq=False)
class Gripper:
    """Finger kinematics (Pinocchio, mimic joints honoured) plus contact surfaces.

    Build one with :func:`isf.load_gripper`; the constructor takes already
    parsed parts.

    Attributes:
        name: bundled name or URDF file stem.
        model: the Pinocchio model, fixed base at the URDF root link, built with
            ``mimic=True`` so ``model.nq`` counts actuated joints only.
        surfaces: the tagged contact surfaces.
        q_initial: the initial (open) configuration, shape (n_joints,).
        geometries: collision geometry of every link, for collision checks.
        urdf_path: the file it was loaded from, if any.
        palm_link: link that approaches the object (``<isf:gripper palm_link>``).
        approach: unit approach direction in the palm link frame, or None.
        tcp_link: the link the tool-centre point is declared in (``<isf:gripper tcp_link>``,
            rigidly attached to the root link), or None when the URDF declares none (then
            :attr:`T_root_tcp` is the default documented there).
        T_link_tcp: the tool-centre-point frame in ``tcp_link``'s frame (``tcp_origin``),
            (4, 4), or None.
        mimic: the mimic joints, ``{follower: Mimic(leader, multiplier, offset)}`` (the
            ``Mimic`` records the URDF reader makes), ``q_follower = multiplier * q_leader +
            offset``.
        closing: the sign of the motion of each actuated joint that closes its finger
            (``<isf:closing joint sign>``), by joint name: +1 or -1, or 0 for a joint that holds
            its value while the others close; joints not declared are missing
            (:meth:`suggested_closing` derives them from the contact normals).
    """

    name: str
    model: pin.Model
    surfaces: tuple[ContactSurface, ...]
    q_initial: np.ndarray
    geometries: tuple[LinkGeometry, ...] = ()
    urdf_path: Path | None = None
    palm_link: str | None = None
    approach: np.ndarray | None = None
    tcp_link: str | None = None
    T_link_tcp: np.ndarray | None = None
    mimic: dict = field(default_factory=dict)  # {follower name: Mimic}
    closing: dict[str, float] = field(default_factory=dict)
    _local: threading.local = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.model.nq != self.model.nv:
            raise ValueError("isf supports revolute and prismatic joints only (nq must equal nv)")
        self._local = threading.local()  # Pinocchio's Data per thread: see _pin_data
        # Compiled kinematics for frame_kinematics_many; None keeps the Pinocchio loop.
        self._chain = KinematicChain.from_model(self.model)
        self.q_initial = np.asarray(self.q_initial, dtype=float).copy()
        names, idx, rotates = [], [], []
        for jid in range(1, self.model.njoints):
            joint = self.model.joints[jid]
            if joint.nq > 0:
                names.append(self.model.names[jid])
                idx.append(joint.idx_q)
                # JointModelRX/RY/RZ/RevoluteUnaligned turn their link; P* slide it.
                rotates.append(joint.shortname().removeprefix("JointModel").startswith("R"))
        order = np.argsort(idx)
        self.joint_names: tuple[str, ...] = tuple(names[i] for i in order)
        self.revolute = np.array([rotates[i] for i in order], dtype=bool)
        """True for revolute joints (they turn normals), shape (n_joints,)."""
        self.lower = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper = np.array(self.model.upperPositionLimit, dtype=float)
        # Stack every surface into one array; remember which link frame, which
        # surface and which farthest-point rank each point has.
        links = sorted({s.link for s in self.surfaces}, key=[s.link for s in self.surfaces].index)
        self.contact_links: tuple[str, ...] = tuple(links)
        """The links that carry contact surfaces, in order of first appearance."""
        self._link_frames = np.array(
            [self.model.getFrameId(link) for link in links], dtype=np.int64
        )
        link_of = {link: k for k, link in enumerate(links)}
        self.points_link = np.concatenate([s.points for s in self.surfaces]).astype(float)
        self.normals_link = np.concatenate([s.normals for s in self.surfaces]).astype(float)
        self.point_link = np.concatenate(
            [np.full(len(s.points), link_of[s.link]) for s in self.surfaces]
        )
        self.point_surface = np.concatenate(
            [np.full(len(s.points), k) for k, s in enumerate(self.surfaces)]
        )
        self.point_rank = np.concatenate([np.arange(len(s.points)) for s in self.surfaces])
        self._points_of_link = [np.flatnonzero(self.point_link == k) for k in range(len(links))]
        self._moving_joints = self._actuated_joints_of_links()

    def _actuated_joints_of_links(self) -> dict[str, frozenset[str]]:
        """The actuated joints between each link and the root, a mimic joint standing for its
        leader, by link (frame) name."""
        out: dict[str, frozenset[str]] = {}
        for frame in self.model.frames:
            if frame.type != pin.FrameType.BODY:
                continue
            joints, joint = set(), frame.parentJoint
            while joint > 0:
                name = self.model.names[joint]
                joints.add(self.mimic[name].joint if name in self.mimic else name)
                joint = self.model.parents[joint]
            out.setdefault(frame.name, frozenset(joints & set(self.joint_names)))
        return out

    # ------------------------------------------------------------ robot frames
    @property
    def T_root_tcp(self) -> np.ndarray:
        """Pose of the tool-centre-point frame ``tcp`` in the gripper (root link) frame, (4, 4).

        Declared (``<isf:gripper tcp_link tcp_origin>``): ``T_root_link @ T_link_tcp`` with the
        link's pose at :attr:`q_initial` (the link is rigidly attached to the root, so any
        configuration gives the same). Not declared: the centre (mean) of the contact-surface
        points at :attr:`q_initial`, with the root link's axes.
        """
        T = np.eye(4)
        if self.tcp_link is None:
            T[:3, 3] = self.contact_points(self.q_initial)[0].mean(axis=0)
            return T
        return self.link_poses(self.q_initial)[self.tcp_link] @ self.T_link_tcp

    @property
    def approach_root(self) -> np.ndarray:
        """The unit approach direction in the gripper frame, shape (3,).

        The declared ``approach`` turned from the palm link frame; without one, from the root
        origin toward :attr:`T_root_tcp`'s origin (the root's +z when they coincide).
        """
        if self.approach is not None:
            R = (np.eye(3) if self.palm_link is None
                 else self.link_poses(self.q_initial)[self.palm_link][:3, :3])
            return R @ np.asarray(self.approach, dtype=float)
        p = self.T_root_tcp[:3, 3]
        norm = float(np.linalg.norm(p))
        return p / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])

    @property
    def q_open(self) -> np.ndarray:
        """The joint vector with the fingers opened, shape (n_joints,).

        Each actuated joint at the limit (lower or upper) that spreads the contact-surface
        points the most from their centre, the others at :attr:`q_initial`; a joint that does
        not move them stays at its initial value.
        """
        q_open = self.q_initial.copy()

        def spread(q: np.ndarray) -> float:
            points = self.contact_points(q)[0]
            return float(np.linalg.norm(points - points.mean(axis=0), axis=1).mean())

        base = spread(self.q_initial)
        for j in range(self.n_joints):
            best, best_spread = self.q_initial[j], base
            for limit in (self.lower[j], self.upper[j]):
                q = self.q_initial.copy()
                q[j] = limit
                if (s := spread(q)) > best_spread + 1e-9:
                    best, best_spread = limit, s
            q_open[j] = best
        return q_open

    def suggested_closing(self, q: np.ndarray | None = None) -> dict[str, float]:
        """The closing sign of each actuated joint that moves a contact surface, by name.

        A finger closes along its contact surface's outward normal: the sign is that of
        ``sum_i n_i . dp_i/dq_j`` over the contact points ``p_i`` (normals ``n_i``, gripper frame)
        at ``q`` (default :attr:`q_initial`), and 0 (the joint holds) when that sum over
        ``sum_i |dp_i/dq_j|`` is below ``CLOSING_HOLD_COSINE`` (0.2) in magnitude. Joints that
        move no contact point are left out.
        """
        kin = self.contact_kinematics(self.q_initial if q is None else np.asarray(q, dtype=float))
        push = np.einsum("mk,mkj->j", kin.normals, kin.J_points)
        speed = np.linalg.norm(kin.J_points, axis=1).sum(axis=0)
        return {name: float(np.sign(push[j])) if abs(push[j]) >= CLOSING_HOLD_COSINE * speed[j]
                else 0.0
                for j, name in enumerate(self.joint_names) if speed[j] > 1e-9}

    def closing_signs(self, q: np.ndarray | None = None) -> np.ndarray:
        """The sign of the motion that closes each actuated joint's finger, +1 or -1, or 0 for a
        joint that holds its value while the others close, shape (n_joints,): the declared
        :attr:`closing` where there is one, else :meth:`suggested_closing` at ``q`` (default
        :attr:`q_initial`), else (a joint that moves no contact point) +1."""
        signs = np.ones(self.n_joints)
        suggested = None
        for j, name in enumerate(self.joint_names):
            if name in self.closing:
                signs[j] = self.closing[name]
            else:
                if suggested is None:
                    suggested = self.suggested_closing(q)
                signs[j] = suggested.get(name, 1.0)
        return signs

    def closing_joints_of_links(self, q: np.ndarray | None = None) -> dict[str, frozenset[str]]:
        """For every link, the actuated joints that move it as the fingers close (those whose
        :meth:`closing_signs` at ``q`` is not 0, a mimic joint standing for its leader), by
        link name; an empty set for a link no closing joint moves (the palm)."""
        holds = {name for name, sign in zip(self.joint_names, self.closing_signs(q)) if sign == 0}
        return {link: joints - holds for link, joints in self._moving_joints.items()}

    def joint_state(self, q: np.ndarray) -> dict[str, float]:
        """Every moving joint's value by URDF name at ``q`` (n_joints,): the actuated joints
        and their mimic followers (``multiplier * q_leader + offset``), metres or radians."""
        values = self.joints(q)
        values.update({name: m.multiplier * values[m.joint] + m.offset
                       for name, m in self.mimic.items() if m.joint in values})
        return values

    # ------------------------------------------------------------------ sizes
    @property
    def chain(self) -> KinematicChain | None:
        """The compiled kinematics, or None when the model has joints it does not cover
        (then Pinocchio computes everything)."""
        return self._chain

    @property
    def link_frames(self) -> np.ndarray:
        """Pinocchio frame ids of :attr:`contact_links`, (L,)."""
        return self._link_frames

    @property
    def n_joints(self) -> int:
        """Number of actuated joints (the length of ``q``)."""
        return self.model.nq

    @property
    def n_points(self) -> int:
        """Total number of contact-surface points over all surfaces."""
        return len(self.points_link)

    def level_mask(self, level: int) -> np.ndarray:
        """Points kept at pyramid level ``level`` (every surface keeps ``ceil(N / 2**level)``).

        Returns:
            boolean mask, shape (n_points,).
        """
        sizes = np.array([len(s.points) for s in self.surfaces])
        keep = np.maximum(1, np.ceil(sizes / 2.0**level)).astype(int)
        return self.point_rank < keep[self.point_surface]

    def joints(self, q: np.ndarray) -> dict[str, float]:
        """Joint values by name, metres or radians."""
        return {n: float(v) for n, v in zip(self.joint_names, np.asarray(q, dtype=float))}

    def clip(self, q: np.ndarray) -> np.ndarray:
        """``q`` clipped into the joint limits, shape (n_joints,)."""
        return np.clip(np.asarray(q, dtype=float), self.lower, self.upper)

    # ------------------------------------------------------------- kinematics
    def _pin_data(self) -> pin.Data:
        """This thread's Pinocchio ``Data`` (Pinocchio writes its results into it, so threads
        planning with one gripper each need their own)."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data

    def link_poses(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Pose of every link in the gripper frame, ``T_gripper_link``, each (4, 4)."""
        data = self._pin_data()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=float))
        poses = {}
        for fid, frame in enumerate(self.model.frames):
            if frame.type == pin.FrameType.BODY:
                poses[frame.name] = data.oMf[fid].homogeneous.copy()
        return poses

    def link_kinematics(self, q: np.ndarray) -> LinkKinematics:
        """Poses and Jacobians of the contact links at ``q`` (n_joints,) (one Pinocchio pass)."""
        return LinkKinematics(*(a[0] for a in self.link_kinematics_many(np.asarray(q)[None])))

    def link_kinematics_many(self, Q: np.ndarray) -> LinkKinematics:
        """:meth:`link_kinematics` of B joint vectors ``Q`` (B, n_joints): every array gains a
        leading axis of length B."""
        return self.frame_kinematics_many(Q, self._link_frames)

    def frame_kinematics_many(self, Q: np.ndarray, frames: np.ndarray) -> LinkKinematics:
        """Poses and Jacobians of any Pinocchio frames (ids (F,)) at B joint vectors ``Q``
        (B, n_joints), gripper frame: arrays (B, F, ...) as in :class:`LinkKinematics`.

        One compiled call (:mod:`isf.gripper.chain`) when the model's joints allow it, else a loop
        of Pinocchio calls; both give Pinocchio's LOCAL_WORLD_ALIGNED frame Jacobians."""
        model, data = self.model, self._pin_data()
        Q = np.asarray(Q, dtype=float)
        Q = Q.reshape(len(Q) if Q.ndim == 2 else 1, model.nq)  # (-1, 0) cannot be inferred
        if self._chain is not None:
            return LinkKinematics(*self._chain.frame_kinematics(Q, frames))
        frames = np.asarray(frames, dtype=int).tolist()
        H = np.empty((len(Q), len(frames), 4, 4))
        J = np.empty((len(Q), len(frames), 6, model.nv))
        world_aligned, placements = pin.LOCAL_WORLD_ALIGNED, data.oMf
        for q, H_b, J_b in zip(Q, H, J):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            for k, fid in enumerate(frames):
                H_b[k] = placements[fid].homogeneous
                if model.nv:  # pin 4.1's getFrameJacobian crashes on a model without joints
                    J_b[k] = pin.getFrameJacobian(model, data, fid, world_aligned).reshape(6, -1)
        R, p = np.ascontiguousarray(H[:, :, :3, :3]), np.ascontiguousarray(H[:, :, :3, 3])
        J_linear, J_angular = np.ascontiguousarray(J[:, :, :3]), np.ascontiguousarray(J[:, :, 3:])
        return LinkKinematics(R, p, J_linear, J_angular)

    def contact_kinematics(
        self, q: np.ndarray, mask: np.ndarray | None = None
    ) -> ContactKinematics:
        """Contact points, normals and their Jacobians at ``q``, gripper frame.

        Args:
            q: joint vector, shape (n_joints,).
            mask: optional boolean mask or index array selecting points.

        Returns:
            :class:`ContactKinematics` for the selected points.
        """
        links = self.link_kinematics(q)
        sel = slice(None) if mask is None else mask
        li = self.point_link[sel]
        Rl = links.rotations[li]
        r = np.einsum("nij,nj->ni", Rl, self.points_link[sel])
        normals = np.einsum("nij,nj->ni", Rl, self.normals_link[sel])
        Jv = links.J_linear[li]
        Jw = links.J_angular[li]
        # v_point = v_link + w x r  ->  J_point = Jv + Jw x r, column by column
        rx, ry, rz = r[:, 0, None], r[:, 1, None], r[:, 2, None]
        wx, wy, wz = Jw[:, 0], Jw[:, 1], Jw[:, 2]
        J_points = Jv + np.stack([wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx], axis=1)
        return ContactKinematics(r + links.positions[li], normals, J_points, Jw)

    def contact_points(
        self, q: np.ndarray, mask: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Contact points and normals at ``q`` in the gripper frame, each (n_selected, 3).

        Args:
            q: joint vector, shape (n_joints,).
            mask: optional boolean mask or index array selecting points (default all).
        """
        links = self.link_kinematics(q)
        points = np.empty_like(self.points_link)
        normals = np.empty_like(self.normals_link)
        for k, idx in enumerate(self._points_of_link):
            R = links.rotations[k]
            points[idx] = self.points_link[idx] @ R.T + links.positions[k]
            normals[idx] = self.normals_link[idx] @ R.T
        if mask is None:
            return points, normals
        return points[mask], normals[mask]
