"""Contact-point Jacobians of loaded grippers against central finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from isf.gripper.loading import load_gripper

# Two fingers with two revolute joints each; tilted joint axes and origins so that
# no Jacobian entry is trivially zero. Pads are boxes on the distal links; the
# proximal links carry a second surface.
TWO_FINGERS = """<robot name="two_fingers" xmlns:isf="urn:isf:gripper:1">
  <link name="palm"><collision><geometry><box size="0.08 0.04 0.02"/></geometry></collision></link>
  {fingers}
  <isf:contact name="a_tip" link="a_distal" normal="0 -1 0" points="32"/>
  <isf:contact name="b_tip" link="b_distal" normal="0 -1 0" points="32"/>
  <isf:contact name="a_side" link="a_proximal" normal="0 -1 0" points="16"/>
</robot>"""

FINGER = """
  <link name="{f}_proximal"><collision><origin xyz="0 0 0.02"/>
    <geometry><box size="0.012 0.01 0.04"/></geometry></collision></link>
  <link name="{f}_distal"><collision><origin xyz="0.001 -0.002 0.015" rpy="0.1 0 0.2"/>
    <geometry><box size="0.01 0.008 0.03"/></geometry></collision></link>
  <joint name="{f}_proximal_joint" type="revolute"><parent link="palm"/><child link="{f}_proximal"/>
    <origin xyz="{x} 0.005 0.02" rpy="0 0 {yaw}"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-0.5" upper="1.2" effort="1" velocity="1"/></joint>
  <joint name="{f}_distal_joint" type="revolute"><parent link="{f}_proximal"/><child link="{f}_distal"/>
    <origin xyz="0 0.001 0.04" rpy="0.2 -0.1 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>"""

# A parallel gripper driven by one prismatic joint: the right jaw mimics it with
# multiplier -1 and an offset, and a tip on the right jaw turns with it (revolute mimic).
MIMIC_PARALLEL = """<robot name="mimic_parallel" xmlns:isf="urn:isf:gripper:1">
  <link name="palm"><collision><geometry><box size="0.1 0.02 0.02"/></geometry></collision></link>
  <link name="left"><collision>
    <origin xyz="0 0 0.02"/><geometry><box size="0.01 0.01 0.04"/></geometry></collision></link>
  <link name="right"><collision>
    <origin xyz="0 0 0.02"/><geometry><box size="0.01 0.01 0.04"/></geometry></collision></link>
  <link name="right_tip"><collision>
    <origin xyz="0 0 0.01"/><geometry><box size="0.01 0.01 0.02"/></geometry></collision></link>
  <joint name="jaw" type="prismatic"><parent link="palm"/><child link="left"/>
    <origin xyz="0 0 0.03"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="jaw_mimic" type="prismatic"><parent link="palm"/><child link="right"/>
    <origin xyz="0 0 0.03" rpy="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="jaw" multiplier="-1" offset="0.005"/></joint>
  <joint name="tip_mimic" type="revolute"><parent link="right"/><child link="right_tip"/>
    <origin xyz="0 0 0.04"/><axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
    <mimic joint="jaw" multiplier="12" offset="0.2"/></joint>
  <isf:contact name="left_pad" link="left" normal="0 1 0" points="32"/>
  <isf:contact name="right_pad" link="right" normal="0 -1 0" points="32"/>
  <isf:contact name="tip_pad" link="right_tip" normal="0 -1 0" points="32"/>
</robot>"""


def _gripper(tmp_path, text):
    path = tmp_path / "g.urdf"
    path.write_text(text)
    return load_gripper(path)


def _check_against_finite_differences(gripper, n_samples=4, h=1e-6):
    rng = np.random.default_rng(1234)
    for _ in range(n_samples):
        q = rng.uniform(gripper.lower, gripper.upper)
        kin = gripper.contact_kinematics(q)
        J_fd = np.empty_like(kin.J_points)
        dN_fd = np.empty_like(kin.J_points)
        for k in range(gripper.n_joints):
            dq = np.zeros(gripper.n_joints)
            dq[k] = h
            p_plus, n_plus = gripper.contact_points(q + dq)
            p_minus, n_minus = gripper.contact_points(q - dq)
            J_fd[:, :, k] = (p_plus - p_minus) / (2 * h)
            dN_fd[:, :, k] = (n_plus - n_minus) / (2 * h)
        np.testing.assert_allclose(kin.J_points, J_fd, atol=1e-8)
        dN = np.cross(kin.J_rotation, kin.normals[:, :, None], axisa=1, axisb=1, axisc=1)
        np.testing.assert_allclose(dN, dN_fd, atol=1e-8)
        assert np.abs(J_fd).max() > 1e-3  # the configuration really moves the points


def test_two_revolute_fingers(tmp_path):
    fingers = FINGER.format(f="a", x=0.03, yaw=0.0) + FINGER.format(f="b", x=-0.03, yaw=np.pi)
    gripper = _gripper(tmp_path, TWO_FINGERS.format(fingers=fingers))
    assert gripper.n_joints == 4
    _check_against_finite_differences(gripper)


def test_mimic_parallel_gripper(tmp_path):
    gripper = _gripper(tmp_path, MIMIC_PARALLEL)
    assert gripper.n_joints == 1
    _check_against_finite_differences(gripper)
    # the mimic jaw moves opposite to the leader, along its own yawed axis
    kin = gripper.contact_kinematics(gripper.q_initial)
    right = gripper.point_surface == 1
    axis = np.array([-np.sin(0.3), np.cos(0.3), 0.0])
    np.testing.assert_allclose(
        kin.J_points[right, :, 0], np.tile(-axis, (right.sum(), 1)), atol=1e-12
    )
    left = gripper.point_surface == 0
    np.testing.assert_allclose(
        kin.J_points[left, :, 0], np.tile([0, 1, 0], (left.sum(), 1)), atol=1e-12
    )


@pytest.mark.parametrize("mask_kind", ["bool", "index"])
def test_masked_kinematics_are_a_subset(tmp_path, mask_kind):
    gripper = _gripper(tmp_path, MIMIC_PARALLEL)
    q = gripper.q_initial
    full = gripper.contact_kinematics(q)
    mask = gripper.level_mask(2)
    sel = mask if mask_kind == "bool" else np.flatnonzero(mask)
    part = gripper.contact_kinematics(q, sel)
    for a, b in zip(part, full):
        np.testing.assert_allclose(a, b[sel], atol=0)
