"""A kinematic tree read off a Pinocchio model, evaluated by a compiled (numba) kernel.

:class:`KinematicChain` copies what forward kinematics needs out of a
``pin.Model`` into flat arrays: per joint its parent, constant placement in
the parent joint's frame, motion (revolute about or prismatic along an axis)
and the entry of ``q`` it reads; per frame its parent joint and placement.
:meth:`KinematicChain.frame_kinematics` then returns frame poses and frame
Jacobians for a batch of joint vectors in one compiled call; the result equals
``pin.computeJointJacobians`` + ``pin.updateFramePlacements`` +
``pin.getFrameJacobian(..., pin.LOCAL_WORLD_ALIGNED)``: the kernel repeats
Pinocchio 4.1's arithmetic in its order, and agrees with the x86-64 wheel bit
for bit on every bundled and vendor gripper (elsewhere: up to round-off).

Supported joints: RX/RY/RZ, RevoluteUnaligned, PX/PY/PZ, PrismaticUnaligned,
revolute-unbounded (RUBX/RUBY/RUBZ, RevoluteUnboundedUnaligned: ``q`` holds
cos and sin) and mimic joints of the revolute and prismatic ones (value =
``scaling * q[primary] + offset``; their Jacobian column adds, times
``scaling``, to the primary's column). Other joints make
:meth:`KinematicChain.from_model` return None.

Frames: the model's root ("world", joint 0) frame; positions in metres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..compiled.kernels import kernel
from ..exceptions import InvalidInputError

__all__ = ["ChainArrays", "FrameKinematics", "KinematicChain", "compiled_frame_kinematics"]

_log = logging.getLogger(__name__)

# Motion kinds of a joint, as stored in KinematicChain.joint_ints[:, 1].
_FIXED, _REVOLUTE, _PRISMATIC, _UNBOUNDED = 0, 1, 2, 3
_ONE_DOF = {"RX", "RY", "RZ", "RevoluteUnaligned", "PX", "PY", "PZ", "PrismaticUnaligned"}
_UNBOUNDED_NAMES = {"RUBX", "RUBY", "RUBZ", "RevoluteUnboundedUnaligned"}


def _se3_rows(M: pin.SE3) -> np.ndarray:
    """``[R | p]`` of an SE3, shape (3, 4)."""
    return np.hstack([M.rotation, M.translation[:, None]])


def _joint_row(model: pin.Model, jid: int) -> tuple[list[int], list[float], np.ndarray] | None:
    """Integer row, real row and (3, 4) placement of joint ``jid``, or None if unsupported."""
    joint = model.joints[jid]
    kind_name = joint.shortname().removeprefix("JointModel")
    placement = model.jointPlacements[jid]
    parent, mimic = model.parents[jid], kind_name == "Mimic"
    scale, offset = 1.0, 0.0
    if mimic:
        spec = joint.extract()
        scale, offset = float(spec.scaling), float(spec.offset)
    elif kind_name not in _ONE_DOF | _UNBOUNDED_NAMES:
        return None
    data = joint.createData()
    joint.calc(data, pin.neutral(model))
    S = np.asarray(data.S, dtype=float).reshape(6)
    if mimic:
        if scale == 0.0:  # the joint sits still at its offset: fold it into the placement
            return [parent, _FIXED, 0, 0, -1, 1], [0.0] * 5, _se3_rows(placement * pin.SE3(data.M))
        S = S / scale  # pin's mimic S is scaling * (the mimicked motion); exact for scaling = +-2^k
    linear, angular = S[:3], S[3:]
    if not linear.any() and angular.any():
        kind, axis = (_UNBOUNDED if kind_name in _UNBOUNDED_NAMES else _REVOLUTE), angular
    elif linear.any() and not angular.any() and kind_name not in _UNBOUNDED_NAMES:
        kind, axis = _PRISMATIC, linear
    else:  # e.g. a mimic of a helical joint
        return None
    # pin computes RX/PY/RUBZ... by their own formulas, and a mimic of RX/RY/RZ gets a
    # rotation matrix with an exact 1 on its axis.
    if mimic:
        nonzero = np.flatnonzero(axis)
        axis_index = int(nonzero[0]) if len(nonzero) == 1 and axis[nonzero[0]] == 1.0 else -1
    else:
        axis_index = "XYZ".find(kind_name[-1])
    ints = [parent, kind, joint.idx_q, joint.idx_v, axis_index, int(mimic)]
    return ints, [scale, offset, *axis], _se3_rows(placement)


class ChainArrays(NamedTuple):
    """The arrays of a :class:`KinematicChain` that :func:`compiled_frame_kinematics` reads
    (fields as the chain's attributes of the same names)."""

    nv: int
    joint_ints: np.ndarray
    joint_reals: np.ndarray
    joint_placements: np.ndarray
    frame_joints: np.ndarray
    frame_placements: np.ndarray


class FrameKinematics(NamedTuple):
    """Poses and LOCAL_WORLD_ALIGNED Jacobians of F frames at B joint vectors.

    Attributes:
        rotations: frame orientations in the root frame, (B, F, 3, 3).
        positions: frame origins in the root frame, (B, F, 3), metres.
        J_linear: velocity of each frame origin, (B, F, 3, nv), root frame.
        J_angular: angular velocity of each frame, (B, F, 3, nv), root frame.
    """

    rotations: np.ndarray
    positions: np.ndarray
    J_linear: np.ndarray
    J_angular: np.ndarray


@dataclass(frozen=True, eq=False)
class KinematicChain:
    """A Pinocchio kinematic tree as flat arrays for the compiled kernel.

    Joint 0 is the root (universe); parents precede children.

    Attributes:
        nq: length of a joint vector ``q``.
        nv: number of Jacobian columns.
        joint_ints: per joint ``[parent, kind, q index, v index, axis index, mimic]``,
            shape (J, 6), int64: a mimic joint (mimic = 1) reads its primary's q and v index;
            axis index 0/1/2 marks a joint along a coordinate axis (pin's RX, PY, ...),
            -1 any other.
        joint_reals: per joint ``[scale, offset, axis_x, axis_y, axis_z]``, shape (J, 5):
            the joint value is ``scale * q[q index] + offset`` (rad or m).
        joint_placements: ``[R | p]`` of each joint in its parent joint's frame, (J, 3, 4).
        frame_joints: parent joint of each Pinocchio frame, shape (Fm,), int64.
        frame_placements: ``[R | p]`` of each frame in its parent joint's frame, (Fm, 3, 4).
    """

    nq: int
    nv: int
    joint_ints: np.ndarray
    joint_reals: np.ndarray
    joint_placements: np.ndarray
    frame_joints: np.ndarray
    frame_placements: np.ndarray

    @classmethod
    def from_model(cls, model: pin.Model) -> KinematicChain | None:
        """Read the tree of ``model``; None (logged at debug level) if a joint is unsupported."""
        ints, reals = [[0, _FIXED, 0, 0, -1, 0]], [[0.0] * 5]
        placements = [_se3_rows(pin.SE3.Identity())]
        for jid in range(1, model.njoints):
            row = _joint_row(model, jid)
            if row is None or model.parents[jid] >= jid:
                _log.debug(
                    "%s: joint %r (%s) has no compiled kinematics; using Pinocchio",
                    model.name, model.names[jid], model.joints[jid].shortname(),
                )
                return None
            joint_ints, joint_reals, placement = row
            ints.append(joint_ints)
            reals.append(joint_reals)
            placements.append(placement)
        return cls(
            nq=int(model.nq),
            nv=int(model.nv),
            joint_ints=np.array(ints, dtype=np.int64),
            joint_reals=np.array(reals, dtype=np.float64),
            joint_placements=np.array(placements, dtype=np.float64),
            frame_joints=np.array([f.parentJoint for f in model.frames], dtype=np.int64),
            frame_placements=np.array([_se3_rows(f.placement) for f in model.frames]),
        )

    @property
    def arrays(self) -> ChainArrays:
        """The chain's arrays as :func:`compiled_frame_kinematics` takes them."""
        return ChainArrays(self.nv, self.joint_ints, self.joint_reals, self.joint_placements,
                           self.frame_joints, self.frame_placements)

    def frame_kinematics(self, Q: np.ndarray, frames: np.ndarray) -> FrameKinematics:
        """Poses and LOCAL_WORLD_ALIGNED Jacobians of frames at B joint vectors.

        Args:
            Q: joint vectors, shape (B, nq).
            frames: Pinocchio frame ids, shape (F,).

        Returns:
            The frames' :class:`FrameKinematics`.

        Raises:
            InvalidInputError: ``Q`` is not (B, nq).
            IndexError: a frame id is out of range.
        """
        Q = np.ascontiguousarray(Q, dtype=np.float64)
        if Q.ndim != 2 or Q.shape[1] != self.nq:
            raise InvalidInputError(
                f"Q has shape {Q.shape}; pass joint vectors of shape (B, {self.nq})"
            )
        frames = np.ascontiguousarray(frames, dtype=np.int64).reshape(-1)
        # Read-only arrays would compile a second specialisation of the kernel.
        Q = Q if Q.flags.writeable else Q.copy()
        frames = frames if frames.flags.writeable else frames.copy()
        return compiled_frame_kinematics(Q, frames, self.arrays)


@kernel(inline=True, error_model="python")
def _compose(A, B, out):
    """``out = A * B`` for poses stored as ``[R | p]`` (3, 4), summed as Eigen does in pin's
    build: rows 0-1 in SIMD pairs left to right, row 2 as a scalar reduction tree."""
    for r in range(3):
        for col in range(4):
            t0, t1, t2 = A[r, 0] * B[0, col], A[r, 1] * B[1, col], A[r, 2] * B[2, col]
            out[r, col] = (t0 + t1) + t2 if r < 2 else t0 + (t1 + t2)
        out[r, 3] += A[r, 3]


@kernel(inline=True, error_model="python")
def _local_pose(q, j, ints, reals, placements, M, L):
    """Pose ``[R | p]`` of joint ``j`` in its parent joint's frame at ``q`` (nq,) into ``L``
    (3, 4), as pin's ``jointPlacement * M(q)``; ``M`` (3, 4) is scratch."""
    kind, qi, axis, mimic = ints[j, 1], ints[j, 2], ints[j, 4], ints[j, 5]
    scale, ax, ay, az = reals[j, 0], reals[j, 2], reals[j, 3], reals[j, 4]
    P = placements[j]
    for r in range(3):
        for col in range(4):
            L[r, col] = P[r, col]
    if kind == _FIXED:
        return
    value, c, s = 0.0, 1.0, 0.0
    if kind == _UNBOUNDED:  # pin uses the stored (cos, sin) pair as it is
        c, s = q[qi], q[qi + 1]
    else:
        value = scale * q[qi] + reals[j, 1]  # rad or m
        if kind == _REVOLUTE:
            c, s = np.cos(value), np.sin(value)
    if axis >= 0 and mimic == 0:  # PX/RX... have their own formulas in pin
        if kind == _PRISMATIC:
            for r in range(3):
                L[r, 3] = P[r, 3] + P[r, axis] * value
        else:  # rotation columns: axis kept, next = c next + s after, after = axis x next
            i1, i2 = (axis + 1) % 3, (axis + 2) % 3
            for r in range(3):
                L[r, i1] = c * P[r, i1] + s * P[r, i2]
            L[0, i2] = L[1, axis] * L[2, i1] - L[2, axis] * L[1, i1]
            L[1, i2] = L[2, axis] * L[0, i1] - L[0, axis] * L[2, i1]
            L[2, i2] = L[0, axis] * L[1, i1] - L[1, axis] * L[0, i1]
        return
    for r in range(3):
        M[r, 3] = 0.0
    if kind == _PRISMATIC:
        for r in range(3):
            M[r, 0], M[r, 1], M[r, 2] = 0.0, 0.0, 0.0
            M[r, r] = 1.0
        M[0, 3], M[1, 3], M[2, 3] = ax * value, ay * value, az * value
    else:  # Rodrigues' formula as pin's toRotationMatrix
        t = 1.0 - c
        M[0, 1] = t * ax * ay - s * az
        M[1, 0] = t * ax * ay + s * az
        M[0, 2] = t * ax * az + s * ay
        M[2, 0] = t * ax * az - s * ay
        M[1, 2] = t * ay * az - s * ax
        M[2, 1] = t * ay * az + s * ax
        M[0, 0] = t * ax * ax + c
        M[1, 1] = t * ay * ay + c
        M[2, 2] = t * az * az + c
        if axis >= 0:  # a mimic of RX/RY/RZ: pin's matrix has an exact 1 there
            M[axis, axis] = 1.0
    _compose(P, M, L)


@kernel(error_model="python")
def compiled_frame_kinematics(Q, frames, chain):
    """Compiled body of :meth:`KinematicChain.frame_kinematics`: the :class:`FrameKinematics` of
    ``frames`` (F,) at joint vectors ``Q`` (B, nq) of the chain ``chain`` (:class:`ChainArrays`).

    The arithmetic repeats Pinocchio 4.1's (forwardKinematics, the joints' ``se3Action``,
    computeJointJacobians, getFrameJacobian) operation by operation and in its order.
    """
    nv, ints, reals = chain.nv, chain.joint_ints, chain.joint_reals
    placements = chain.joint_placements
    frame_joints, frame_placements = chain.frame_joints, chain.frame_placements
    B, F, nj, nf = Q.shape[0], frames.shape[0], ints.shape[0], frame_joints.shape[0]
    for k in range(F):
        if frames[k] < 0 or frames[k] >= nf:
            raise IndexError("frame id out of range of the model's frames")
    R_out = np.empty((B, F, 3, 3))
    p_out = np.empty((B, F, 3))
    J_lin = np.zeros((B, F, 3, nv))
    J_ang = np.zeros((B, F, 3, nv))
    oT = np.zeros((nj, 3, 4))  # joint poses [R | p] in the root frame
    lin = np.zeros((nj, 3))  # each joint's Jacobian column in the root frame: velocity of
    ang = np.zeros((nj, 3))  # the point at the root origin, and angular velocity
    M, L, oF = np.empty((3, 4)), np.empty((3, 4)), np.empty((3, 4))
    oT[0, 0, 0] = oT[0, 1, 1] = oT[0, 2, 2] = 1.0
    has_mimic = ints[:, 5].any()
    for b in range(B):
        for j in range(1, nj):
            _local_pose(Q[b], j, ints, reals, placements, M, L)
            _compose(oT[ints[j, 0]], L, oT[j])  # oMi = oMi[parent] * liMi
            kind, axis, mimic = ints[j, 1], ints[j, 4], ints[j, 5]
            T = oT[j]
            # the joint's motion acted into the root frame (pin: oMi.act(S)), scaled for a mimic
            for r in range(3):
                if axis >= 0 and mimic == 0:
                    w = T[r, axis]
                else:
                    t0, t1, t2 = T[r, 0] * reals[j, 2], T[r, 1] * reals[j, 3], T[r, 2] * reals[j, 4]
                    w = (t0 + t1) + t2 if r < 2 else t0 + (t1 + t2)
                if kind == _PRISMATIC:
                    lin[j, r], ang[j, r] = w, 0.0
                else:
                    ang[j, r] = w
            if kind == _REVOLUTE or kind == _UNBOUNDED:  # noqa: SIM109 (compiled); p x w
                lin[j, 0] = T[1, 3] * ang[j, 2] - T[2, 3] * ang[j, 1]
                lin[j, 1] = T[2, 3] * ang[j, 0] - T[0, 3] * ang[j, 2]
                lin[j, 2] = T[0, 3] * ang[j, 1] - T[1, 3] * ang[j, 0]
            if mimic == 1:
                for r in range(3):
                    lin[j, r] *= reals[j, 0]
                    ang[j, r] *= reals[j, 0]
        for k in range(F):
            i = frame_joints[frames[k]]
            _compose(oT[i], frame_placements[frames[k]], oF)  # oMf = oMi * placement
            for r in range(3):
                for col in range(3):
                    R_out[b, k, r, col] = oF[r, col]
                p_out[b, k, r] = oF[r, 3]
            px, py, pz = oF[0, 3], oF[1, 3], oF[2, 3]
            # Pin's order: the supporting joints' own columns first (v_out = v - p x w), then
            # each mimic joint's column added to its primary's (v_out += v; v_out -= p x w),
            # deepest joint first.
            for mimic_pass in range(2 if has_mimic else 1):
                j = i
                while j > 0:
                    if ints[j, 1] != _FIXED and ints[j, 5] == mimic_pass:
                        v = ints[j, 3]
                        wx, wy, wz = ang[j, 0], ang[j, 1], ang[j, 2]
                        pxw = (py * wz - pz * wy, pz * wx - px * wz, px * wy - py * wx)
                        for r in range(3):
                            if mimic_pass == 0:
                                J_lin[b, k, r, v] = lin[j, r] - pxw[r]
                                J_ang[b, k, r, v] = ang[j, r]
                            else:
                                J_lin[b, k, r, v] = (J_lin[b, k, r, v] + lin[j, r]) - pxw[r]
                                J_ang[b, k, r, v] += ang[j, r]
                    j = ints[j, 0]
    return FrameKinematics(R_out, p_out, J_lin, J_ang)
