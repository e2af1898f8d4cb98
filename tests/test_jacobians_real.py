"""Contact Jacobians of real hands against central finite differences.

``Gripper.contact_kinematics`` returns analytic Jacobians (Pinocchio frame Jacobians
plus a lever arm). They are checked, at seeded random configurations inside the
limits, against central differences of the forward kinematics:

* ``J_points[:, :, k]`` against ``(p(q + h e_k) - p(q - h e_k)) / 2h``;
* ``J_rotation[:, :, k] x normals`` against the same difference of the normals;
* ``J_rotation[:, :, k]`` itself against the angular velocity of the point's link,
  ``vee(dR/dq_k R^T)``, from :meth:`Gripper.link_poses` (this also checks the
  rotation about the normal, which the normals alone cannot see, e.g. on a flat pad).

Hands: the bundled ``three-finger`` (6 revolute joints) and ``paper-parallel``
(prismatic, one mimic jaw), and tagged copies of the vendor Robotiq 2F-85 (one joint
driving a five-joint mimic linkage) and Allegro hand (16 joints).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_vendor_grippers import tagged_vendor_gripper

from isf.gripper.loading import load_gripper

H = 1e-6  # finite-difference step, metres or radians
RTOL = 1e-6  # error allowed, relative to the largest entry of the joint's column
ATOL = 1e-9  # floor for columns that are ~0: difference rounding is ~ eps / H = 2e-10
N_CONFIGURATIONS = 3
# The Robotiq pads translate without turning (a four-bar linkage), so their rotation
# Jacobians are zero; whole-link surfaces on links that do turn, through mimic joints on
# both sides, make the rotation check bite.
ROBOTIQ_LINKAGE_TAGS = (
    ("left_inner_finger", "left_inner_finger", ""),
    ("right_outer_finger", "right_outer_finger", ""),
    ("right_inner_knuckle", "right_inner_knuckle", ""),
)


HANDS = ["three-finger", "paper-parallel", "robotiq-2f-85", "allegro-right"]


@pytest.fixture(scope="module", params=HANDS)
def gripper(request, tmp_path_factory):
    name = request.param
    if name in ("three-finger", "paper-parallel"):
        return load_gripper(name, points_per_surface=64)
    extra = ROBOTIQ_LINKAGE_TAGS if name == "robotiq-2f-85" else ()
    path, package_dirs = tagged_vendor_gripper(name, tmp_path_factory.mktemp(name), extra)
    return load_gripper(path, package_dirs=package_dirs, points_per_surface=64)


def _vee_rate(R_plus: np.ndarray, R_minus: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Angular velocity w with dR/dq = [w]x R, from a central difference of rotations."""
    W = (R_plus - R_minus) / (2 * H) @ R.T
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


def _assert_close(analytic: np.ndarray, numeric: np.ndarray, what: str) -> None:
    """One joint's column, shape (M, 3): max error within RTOL of its largest entry (+ ATOL)."""
    scale = np.abs(numeric).max()
    error = np.abs(analytic - numeric).max()
    assert error <= RTOL * scale + ATOL, f"{what}: error {error:.3g} for scale {scale:.3g}"


def test_jacobians_match_central_differences(gripper):
    rng = np.random.default_rng(20240611)
    n = gripper.n_joints
    links = [s.link for s in gripper.surfaces]
    point_link = np.array([links[k] for k in gripper.point_surface])
    moved = np.zeros(n)
    for _ in range(N_CONFIGURATIONS):
        q = rng.uniform(gripper.lower + H, gripper.upper - H)
        kin = gripper.contact_kinematics(q)
        poses = gripper.link_poses(q)
        # a random mask must give the same rows as the full set
        mask = rng.random(gripper.n_points) < 0.5
        part = gripper.contact_kinematics(q, mask)
        for a, b in zip(part, kin):
            np.testing.assert_array_equal(a, b[mask])
        for k in range(n):
            dq = np.zeros(n)
            dq[k] = H
            p_plus, n_plus = gripper.contact_points(q + dq)
            p_minus, n_minus = gripper.contact_points(q - dq)
            joint = gripper.joint_names[k]
            _assert_close(kin.J_points[:, :, k], (p_plus - p_minus) / (2 * H), f"J_points {joint}")
            dn = np.cross(kin.J_rotation[:, :, k], kin.normals)
            _assert_close(dn, (n_plus - n_minus) / (2 * H), f"d normals / d {joint}")
            plus, minus = gripper.link_poses(q + dq), gripper.link_poses(q - dq)
            w = np.empty((gripper.n_points, 3))
            for link in set(links):
                R_plus, R_minus = plus[link][:3, :3], minus[link][:3, :3]
                w[point_link == link] = _vee_rate(R_plus, R_minus, poses[link][:3, :3])
            _assert_close(kin.J_rotation[:, :, k], w, f"J_rotation {joint}")
            if not gripper.revolute[k]:  # a prismatic joint (and its mimics) turns nothing
                np.testing.assert_allclose(kin.J_rotation[:, :, k], 0.0, atol=1e-12)
            moved[k] = max(moved[k], np.abs(kin.J_points[:, :, k]).max())
    assert np.all(moved > 1e-3), f"joints that move no contact point: {moved}"
