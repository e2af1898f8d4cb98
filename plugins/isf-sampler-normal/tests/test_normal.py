"""Tests of the ``normal`` sampler plugin: conformance kit, analytic geometry, discovery."""

from __future__ import annotations

import numpy as np
import pytest

from isf.exceptions import GripperDescriptionError
from isf.samplers import available_samplers, get_sampler
from isf.testing import canonical_gripper, canonical_object, check_sampler
from isf_sampler_normal import NormalSampler

# The canonical gripper's palm is mounted with rpy = (0.3, 0, pi/2) at (0.01, 0, 0.02);
# its pads are centred 0.05 m along the palm's z axis. Hence, in the gripper frame:
TILT = 0.3
APPROACH_IN_GRIPPER = np.array([np.sin(TILT), 0.0, np.cos(TILT)])  # Rz(pi/2) Rx(0.3) e_z
GRASP_CENTRE = np.array([0.01, 0.0, 0.02]) + 0.05 * APPROACH_IN_GRIPPER


@pytest.mark.parametrize(
    ("palm_link", "approach"),
    [("palm", (0, 0, 1)), ("base_link", (0, 0, 1)), (None, (1, 0, 0)), ("palm", None)],
)
def test_conformance(palm_link, approach):
    check_sampler(NormalSampler, gripper=canonical_gripper(palm_link=palm_link, approach=approach))


def test_conformance_on_sphere():
    check_sampler(NormalSampler(), obj=canonical_object("sphere"))


def _propose(gripper, obj, n=200, seed=1):
    sampler = NormalSampler()
    rng = np.random.default_rng(seed)
    sampler.reset(obj, gripper, rng)
    return sampler.propose(n, rng)


@pytest.mark.parametrize(
    ("palm_link", "approach_gripper"),
    [("palm", APPROACH_IN_GRIPPER), ("base_link", np.array([0.0, 0.0, 1.0]))],
)
def test_approach_axis_points_into_the_surface(palm_link, approach_gripper):
    obj = canonical_object("sphere")
    for p in _propose(canonical_gripper(palm_link=palm_link), obj):
        T = p.T_object_gripper
        k = p.record["point"]
        np.testing.assert_allclose(T[:3, :3] @ approach_gripper, -obj.normals[k], atol=1e-9)
        np.testing.assert_allclose(T[:3, :3] @ GRASP_CENTRE + T[:3, 3], obj.points[k], atol=1e-12)


def test_spin_about_the_normal_is_uniform():
    obj = canonical_object("box", n_points=600)
    angles = []
    for p in _propose(canonical_gripper(palm_link="base_link"), obj, n=400):
        if obj.normals[p.record["point"]][2] > 0.99:  # top face: the approach axis is -z
            x_axis = p.T_object_gripper[:3, 0]
            angles.append(np.arctan2(x_axis[1], x_axis[0]))
    assert len(angles) > 50
    # mean resultant length of uniform angles ~ 1/sqrt(m); a fixed spin would give 1
    assert abs(np.mean(np.exp(1j * np.array(angles)))) < 4 / np.sqrt(len(angles))


def test_without_approach_orientation_is_random_but_centre_is_placed():
    obj = canonical_object("box")
    proposals = _propose(canonical_gripper(approach=None), obj, n=50)
    z_axes = np.array([p.T_object_gripper[:3, 2] for p in proposals])
    assert np.linalg.norm(z_axes.mean(axis=0)) < 0.5
    for p in proposals:
        T = p.T_object_gripper
        np.testing.assert_allclose(
            T[:3, :3] @ GRASP_CENTRE + T[:3, 3], obj.points[p.record["point"]], atol=1e-12
        )


def test_unknown_palm_link_is_reported():
    gripper = canonical_gripper(palm_link="wrist")
    with pytest.raises(GripperDescriptionError, match="palm_link 'wrist'.*base_link"):
        NormalSampler().reset(canonical_object(), gripper, np.random.default_rng(0))


def test_reached_through_its_entry_point():
    info = available_samplers()["normal"]
    assert info.distribution == "isf-sampler-normal"
    assert info.value == "isf_sampler_normal:NormalSampler"
    assert type(get_sampler("normal")) is NormalSampler
