"""Initial orientations: the declared approach axis faces the object; random stays available."""

import numpy as np
import pytest

from isf.exceptions import ConfigError
from isf.samplers import RegretSampler, UniformSampler, get_sampler
from isf.samplers.orientation import approach_direction
from isf.testing import canonical_gripper, canonical_object


def _approach_in_object(gripper, proposal):
    return proposal.T_object_gripper[:3, :3] @ approach_direction(gripper)


def test_palm_frame_approach_is_expressed_in_the_gripper_frame():
    gripper = canonical_gripper()  # its palm link is tilted and offset from the root link
    T_gripper_palm = gripper.link_poses(gripper.q_initial)["palm"]
    expected = T_gripper_palm[:3, :3] @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(approach_direction(gripper), expected, atol=1e-12)


def test_uniform_faces_the_surface_point_it_picked():
    gripper, obj = canonical_gripper(), canonical_object("sphere")
    sampler = UniformSampler()
    rng = np.random.default_rng(0)
    sampler.reset(obj, gripper, rng)
    for p in sampler.propose(50, rng):
        normal = obj.normals[p.record["point"]]
        np.testing.assert_allclose(_approach_in_object(gripper, p), -normal, atol=1e-9)


def test_regret_faces_each_cluster_against_its_mean_normal():
    gripper, obj = canonical_gripper(), canonical_object("sphere", n_points=2000)
    sampler = RegretSampler(com_share=0)
    rng = np.random.default_rng(1)
    sampler.reset(obj, gripper, rng)
    for p in sampler.propose(10, rng):
        k = p.record["cluster"]
        mean = obj.normals[sampler.labels == k].mean(axis=0)
        np.testing.assert_allclose(_approach_in_object(gripper, p), -mean / np.linalg.norm(mean), atol=1e-9)


def test_random_orientation_is_the_papers_uniform_rotation():
    gripper, obj = canonical_gripper(), canonical_object("sphere")
    sampler = UniformSampler(orientation="random")
    rng = np.random.default_rng(2)
    sampler.reset(obj, gripper, rng)
    cosines = [float(_approach_in_object(gripper, p) @ -obj.normals[p.record["point"]])
               for p in sampler.propose(2000, rng)]
    # for uniform rotations the cosine is uniform on [-1, 1]: mean 0, variance 1/3
    assert abs(np.mean(cosines)) < 0.05 and abs(np.var(cosines) - 1 / 3) < 0.03


def test_approach_orientation_needs_a_declared_approach():
    gripper, obj = canonical_gripper(approach=None), canonical_object()
    with pytest.raises(ConfigError, match="approach"):
        get_sampler("uniform", orientation="approach").reset(obj, gripper, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="orientation"):
        RegretSampler(orientation="sideways")
    # auto falls back to random for such a gripper
    sampler = UniformSampler()
    sampler.reset(obj, gripper, np.random.default_rng(0))
    assert len(sampler.propose(3, np.random.default_rng(0))) == 3
