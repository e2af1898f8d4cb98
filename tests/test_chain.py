"""The compiled kinematic tree (isf.gripper.chain) against Pinocchio and finite differences.

Oracles: Pinocchio's own ``computeJointJacobians`` / ``updateFramePlacements`` /
``getFrameJacobian(LOCAL_WORLD_ALIGNED)`` loop, written out here; central finite
differences of the compiled poses (positions, and rotation vectors from scipy).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

import isf
from isf import assets
from isf.exceptions import InvalidInputError
from isf.gripper.chain import KinematicChain
from isf.gripper.model import ContactSurface, Gripper

BUNDLED = ("paper-parallel", "flat-parallel", "three-finger")
ATOL = 1e-12

# A chain with every motion the kernel knows: revolute mimics with multiplier and offset,
# a prismatic mimic with offset, an unaligned axis, and a mimic on a branch beside its leader's.
MIMIC_XML = """<robot name="mimics">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/>
  <link name="d"/><link name="e"/>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0.01 0.02 0.03" rpy="0.1 -0.2 0.3"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="jb" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0.05 0 0.01" rpy="0.4 0 -0.1"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="ja" multiplier="-1.5" offset="0.2"/></joint>
  <joint name="jc" type="prismatic"><parent link="b"/><child link="c"/>
    <origin xyz="0 0.04 0" rpy="0 0.3 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.05" effort="1" velocity="1"/></joint>
  <joint name="jd" type="prismatic"><parent link="c"/><child link="d"/>
    <origin xyz="0.02 0 0.02" rpy="0 0 0.5"/><axis xyz="0.6 0 -0.8"/>
    <limit lower="0" upper="0.05" effort="1" velocity="1"/>
    <mimic joint="jc" multiplier="0.5" offset="0.01"/></joint>
  <joint name="je" type="revolute"><parent link="base"/><child link="e"/>
    <origin xyz="-0.03 0 0.02" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="ja" multiplier="2" offset="-0.1"/></joint>
</robot>"""


def pinocchio_kinematics(model: pin.Model, Q: np.ndarray, frames: np.ndarray):
    """The oracle: R (B,F,3,3), p (B,F,3), J_linear and J_angular (B,F,3,nv) from Pinocchio."""
    data = model.createData()
    B, F = len(Q), len(frames)
    R, p = np.empty((B, F, 3, 3)), np.empty((B, F, 3))
    J = np.zeros((B, F, 6, model.nv))
    for b, q in enumerate(Q):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, fid in enumerate(int(f) for f in frames):
            R[b, k] = data.oMf[fid].rotation
            p[b, k] = data.oMf[fid].translation
            if model.nv:
                J_k = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
                J[b, k] = J_k.reshape(6, -1)  # pin returns (6,) when nv = 1
    return R, p, J[:, :, :3], J[:, :, 3:]


def random_q(model: pin.Model, rng: np.random.Generator, B: int) -> np.ndarray:
    """B joint vectors within the model's limits (pin.randomConfiguration would use its own RNG)."""
    return rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, size=(B, model.nq))


def assert_matches_pinocchio(model: pin.Model, Q: np.ndarray, frames: np.ndarray, got) -> None:
    want = pinocchio_kinematics(model, Q, frames)
    for name, g, w in zip(("rotations", "positions", "J_linear", "J_angular"), got, want):
        assert g.shape == w.shape, name
        assert g.dtype == np.float64 and g.flags.c_contiguous, name
        np.testing.assert_allclose(g, w, rtol=0, atol=ATOL, err_msg=name)


def vendor_model(name: str) -> pin.Model:
    try:
        urdf = assets.vendor_gripper(name)
    except assets.AssetFetchError as exc:
        pytest.skip(f"vendor gripper {name!r} is not cached and cannot be fetched: {exc}")
    return pin.buildModelFromUrdf(str(urdf), mimic=True)


def one_surface_gripper(model: pin.Model, link: str) -> Gripper:
    """A Gripper around ``model`` with a single one-point contact surface on ``link``."""
    surface = ContactSurface("pad", link, np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), area=1e-4)
    return Gripper(name=model.name, model=model, surfaces=(surface,), q_initial=np.zeros(model.nq))


# ----------------------------------------------------------------- Pinocchio
@pytest.mark.parametrize("B", [1, 5])
@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_gripper_matches_pinocchio(name, B):
    gripper = isf.load_gripper(name)
    assert KinematicChain.from_model(gripper.model) is not None
    frames = np.arange(len(gripper.model.frames))
    Q = random_q(gripper.model, np.random.default_rng(B), B)
    assert_matches_pinocchio(gripper.model, Q, frames, gripper.frame_kinematics_many(Q, frames))
    # the contact-link path and a single q (1-D) go through the same code
    links = gripper.link_kinematics(Q[0])
    want = pinocchio_kinematics(gripper.model, Q[:1], gripper._link_frames)
    for g, w in zip(links, want):
        np.testing.assert_allclose(g, w[0], rtol=0, atol=ATOL)


@pytest.mark.parametrize("B", [1, 5])
@pytest.mark.parametrize("name", assets.vendor_grippers(include_arms=True))
def test_vendor_model_matches_pinocchio(name, B):
    model = vendor_model(name)
    chain = KinematicChain.from_model(model)
    assert chain is not None
    frames = np.arange(len(model.frames))[::-1]  # any order, repeats allowed
    frames = np.concatenate([frames, frames[:2]])
    Q = random_q(model, np.random.default_rng(10 + B), B)
    assert_matches_pinocchio(model, Q, frames, chain.frame_kinematics(Q, frames))


def test_hand_built_model_matches_pinocchio():
    """RX -> PY -> RevoluteUnaligned -> PrismaticUnaligned -> RUBZ -> RUB unaligned, a side
    branch, and frames."""
    rng = np.random.default_rng(3)

    def placement():
        return pin.SE3(Rotation.random(random_state=rng).as_matrix(), rng.normal(0.0, 0.05, 3))

    model = pin.Model()
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    j1 = model.addJoint(0, pin.JointModelRX(), placement(), "rx")
    j2 = model.addJoint(j1, pin.JointModelPY(), placement(), "py")
    j3 = model.addJoint(j2, pin.JointModelRevoluteUnaligned(*axis), placement(), "ru")
    j4 = model.addJoint(j3, pin.JointModelPrismaticUnaligned(*axis[::-1]), placement(), "pu")
    j5 = model.addJoint(j4, pin.JointModelRUBZ(), placement(), "rubz")
    j6 = model.addJoint(j5, pin.JointModelRevoluteUnboundedUnaligned(), placement(), "rubu")
    j7 = model.addJoint(j1, pin.JointModelRZ(), placement(), "side")
    for jid in (j1, j2, j3, j4, j5, j6, j7, 0):
        model.addFrame(pin.Frame(f"f{jid}", jid, placement(), pin.FrameType.OP_FRAME))
    assert (model.nq, model.nv) == (9, 7)
    chain = KinematicChain.from_model(model)
    assert chain is not None
    Q = rng.uniform(-1.0, 1.0, size=(5, model.nq))
    for col in (4, 6):  # the unbounded joints store (cos, sin)
        angle = rng.uniform(-np.pi, np.pi, size=5)
        Q[:, col], Q[:, col + 1] = np.cos(angle), np.sin(angle)
    frames = np.arange(len(model.frames))
    assert_matches_pinocchio(model, Q, frames, chain.frame_kinematics(Q, frames))


# -------------------------------------------------------- finite differences
def test_mimic_jacobians_match_finite_differences():
    model = pin.buildModelFromXML(MIMIC_XML, mimic=True)
    assert model.nq == 2 and len(model.mimicking_joints) == 3
    chain = KinematicChain.from_model(model)
    assert chain is not None
    frames = np.array([model.getFrameId(link) for link in ("a", "b", "c", "d", "e")])
    Q = random_q(model, np.random.default_rng(7), 5)
    assert_matches_pinocchio(model, Q, frames, chain.frame_kinematics(Q, frames))
    q = np.array([0.3, 0.02])
    _, _, J_lin, J_ang = (a[0] for a in chain.frame_kinematics(q[None], frames))
    h = 1e-6
    for i in range(model.nq):
        dq = np.zeros(model.nq)
        dq[i] = h
        R_plus, p_plus, _, _ = chain.frame_kinematics((q + dq)[None], frames)
        R_minus, p_minus, _, _ = chain.frame_kinematics((q - dq)[None], frames)
        v = (p_plus[0] - p_minus[0]) / (2 * h)
        # R(q + h) R(q - h)^T = exp(2 h [w]x), w in the root frame
        w = Rotation.from_matrix(R_plus[0] @ np.swapaxes(R_minus[0], 1, 2)).as_rotvec() / (2 * h)
        np.testing.assert_allclose(J_lin[:, :, i], v, rtol=0, atol=1e-8)
        np.testing.assert_allclose(J_ang[:, :, i], w, rtol=0, atol=1e-8)
    # link e turns about the root's z axis at twice the rate of ja, and ja does not move it
    np.testing.assert_allclose(J_ang[4, :, 0], [0.0, 0.0, 2.0], atol=1e-15)


# ------------------------------------------------------------ gripper paths
def test_unsupported_joint_keeps_pinocchio_path():
    model = pin.Model()
    placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    jid = model.addJoint(0, pin.JointModelHX(0.01), placement, "screw")  # helical: unsupported
    model.addBodyFrame("finger", jid, pin.SE3.Identity(), 0)
    assert KinematicChain.from_model(model) is None
    gripper = one_surface_gripper(model, "finger")
    Q = np.array([[0.0], [0.4]])
    frames = np.arange(len(model.frames))
    assert_matches_pinocchio(model, Q, frames, gripper.frame_kinematics_many(Q, frames))


def test_model_without_joints():
    model = pin.Model()
    T = pin.SE3(Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix(), np.array([0.01, 0.02, 0.03]))
    model.addFrame(pin.Frame("pad", 0, T, pin.FrameType.OP_FRAME))
    gripper = one_surface_gripper(model, "pad")
    R, p, J_lin, J_ang = gripper.frame_kinematics_many(np.zeros((3, 0)), [model.getFrameId("pad")])
    assert J_lin.shape == J_ang.shape == (3, 1, 3, 0)
    np.testing.assert_array_equal(R, np.broadcast_to(T.rotation, (3, 1, 3, 3)))
    np.testing.assert_array_equal(p, np.broadcast_to(T.translation, (3, 1, 3)))


def test_bad_arguments_are_rejected():
    gripper = isf.load_gripper("three-finger")
    chain = KinematicChain.from_model(gripper.model)
    with pytest.raises(IndexError):
        chain.frame_kinematics(np.zeros((1, 6)), np.array([len(gripper.model.frames)]))
    with pytest.raises(IndexError):
        chain.frame_kinematics(np.zeros((1, 6)), np.array([-1]))
    with pytest.raises(InvalidInputError, match=r"\(B, 6\)"):
        chain.frame_kinematics(np.zeros((1, 5)), np.array([0]))
