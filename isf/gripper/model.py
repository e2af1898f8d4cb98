"""The :class:`Gripper`: finger kinematics and contact surfaces of one URDF.

Frames
------
``gripper``
    The URDF's root link. Every pose a user sees, ``T_object_gripper``, places
    this frame in the object frame. Contact points, normals and Jacobians
    returned here are expressed in it.
``<link>``
    Each URDF link's own frame; contact surfaces are stored in their link's frame.

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
    """

    name: str
    model: pin.Model
    surfaces: tuple[ContactSurface, ...]
    q_initial: np.ndarray
    geometries: tuple[LinkGeometry, ...] = ()
    urdf_path: Path | None = None
    palm_link: str | None = None
    approach: np.ndarray | None = None
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
