"""Distinct grasps first (isf.planning.diversity): duplicates by TCP distance and angle under the
gripper's symmetries, their order, the symmetry detection and the planner's pass."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import isf
from isf.planning.diversity import (
    Diversity,
    detect_symmetry,
    distinct_first,
    symmetry_rotations,
)
from tests._builders import parallel_gripper

IDENTITY = np.eye(3)[None]
HALF_TURN_Z = np.array([np.eye(3), np.diag([-1.0, -1.0, 1.0])])  # order 2 about the TCP's z


def pose(position=(0, 0, 0), rotvec=(0, 0, 0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = position
    return T


def duplicates(poses, rotations=IDENTITY):
    """The pass with the defaults: 1 cm, 30 degrees."""
    return distinct_first(np.array(poses), rotations, 0.01, math.radians(30))


def test_poses_5_mm_apart_are_one_grasp_15_mm_apart_are_two():
    near = duplicates([pose(), pose((0.005, 0, 0))])
    assert near.order.tolist() == [0, 1] and near.duplicate_of.tolist() == [0, 1]
    far = duplicates([pose(), pose((0, 0.015, 0))])
    assert far.duplicate_of.tolist() == [0, 0]


def test_angle_limit():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    within = duplicates([pose(), pose(rotvec=math.radians(25) * axis)])
    beyond = duplicates([pose(), pose(rotvec=math.radians(35) * axis)])
    assert within.duplicate_of.tolist() == [0, 1] and beyond.duplicate_of.tolist() == [0, 0]


def test_half_turn_about_the_approach_axis_is_the_same_grasp_only_for_a_symmetric_gripper():
    turned = pose((0.002, 0, 0), (0, 0, math.pi))  # z: the approach axis of the TCP frame
    assert duplicates([pose(), turned], HALF_TURN_Z).duplicate_of.tolist() == [0, 1]
    assert duplicates([pose(), turned], IDENTITY).duplicate_of.tolist() == [0, 0]
    # a half turn about another axis is a different grasp even for the symmetric gripper
    flipped = pose((0.002, 0, 0), (math.pi, 0, 0))
    assert duplicates([pose(), flipped], HALF_TURN_Z).duplicate_of.tolist() == [0, 0]


def test_distinct_grasps_come_first_and_duplicates_name_the_rank_of_the_better_one():
    a, b, c = pose(), pose((0.05, 0, 0)), pose((0, 0.05, 0))
    a2, a3, b2 = pose((0.003, 0, 0)), pose((0, 0.004, 0)), pose((0.052, 0, 0))
    result = duplicates([a, a2, b, a3, b2, c])
    assert result.order.tolist() == [0, 2, 5, 1, 3, 4]
    assert result.duplicate_of.tolist() == [0, 0, 0, 1, 1, 2]


def test_a_grasp_is_compared_with_distinct_grasps_only():
    """A chain 0 - 8 - 16 mm: the middle repeats the first, the last is 16 mm from the first."""
    result = duplicates([pose(), pose((0.008, 0, 0)), pose((0.016, 0, 0))])
    assert result.order.tolist() == [0, 2, 1] and result.duplicate_of.tolist() == [0, 0, 1]


def square_pad(z_top=0.06, n=15):
    """A 2 cm x (z_top - 4 cm) pad in the x-z plane of the finger link, facing +y."""
    x, z = np.meshgrid(np.linspace(-0.01, 0.01, n), np.linspace(0.04, z_top, n))
    points = np.c_[x.ravel(), np.zeros(x.size), z.ravel()]
    return points, np.tile([0.0, 1.0, 0.0], (len(points), 1))


def test_symmetry_detection():
    assert detect_symmetry(isf.load_gripper("paper-parallel")) == 2
    assert detect_symmetry(isf.load_gripper("three-finger")) == 3
    pad = square_pad()
    mirrored = (pad[0], -pad[1])
    assert detect_symmetry(parallel_gripper(pad, mirrored)) == 2
    short = square_pad(z_top=0.05)  # the right pad half as tall: no half turn maps them
    assert detect_symmetry(parallel_gripper(pad, (short[0], -short[1]))) == 1


def test_symmetry_rotations_turn_about_the_approach_axis():
    gripper = isf.load_gripper("three-finger")
    rotations = symmetry_rotations(gripper, 3)
    axis = gripper.T_root_tcp[:3, :3].T @ gripper.approach_root
    for k, R in enumerate(rotations):
        rotvec = Rotation.from_matrix(R).as_rotvec()
        assert np.linalg.norm(rotvec) == pytest.approx([0, 2 * math.pi / 3, 2 * math.pi / 3][k])
        if k:
            assert np.allclose(np.cross(rotvec, axis), 0, atol=1e-12)


def test_diversity_arguments_are_checked():
    for bad in (dict(distance=-1.0), dict(angle=float("nan")), dict(symmetry=0),
                dict(symmetry="two")):
        with pytest.raises(isf.InvalidInputError):
            Diversity(**bad)
    with pytest.raises(isf.InvalidInputError, match="diversity"):
        isf.plan("paper-parallel", np.zeros((10, 3)), samples=1, diversity=(0.01, 0.5))


def test_plan_lists_distinct_grasps_first(paper_gripper, cylinder):
    """Every duplicate lies within reach of the grasp it names, under a half turn (checked with
    scipy's rotations); no two distinct grasps do; the plain ranking holds the same grasps."""
    result = isf.plan(paper_gripper, cylinder, samples=20, seed=0)
    plain = isf.plan(paper_gripper, cylinder, samples=20, seed=0, diversity=None)
    assert result.diversity.symmetry == 2 and plain.diversity is None
    assert sorted(g.sample_index for g in result.grasps) == \
        sorted(g.sample_index for g in plain.grasps)
    assert all(g.duplicate_of is None for g in plain.grasps)
    T_tcp = [g.T_object_gripper @ paper_gripper.T_root_tcp for g in result.grasps]
    flip = Rotation.from_rotvec([0, 0, math.pi])  # the TCP's z is the approach axis

    def same(i, j):
        a, b = T_tcp[i], T_tcp[j]
        ra, rb = Rotation.from_matrix(a[:3, :3]), Rotation.from_matrix(b[:3, :3])
        angle = min((ra.inv() * rb).magnitude(), (ra.inv() * rb * flip).magnitude())
        return np.linalg.norm(a[:3, 3] - b[:3, 3]) <= 0.01 and angle <= math.radians(30) + 1e-9

    distinct = [i for i, g in enumerate(result.grasps) if g.duplicate_of is None]
    assert distinct == list(range(len(distinct))) and len(distinct) < len(result.grasps)
    assert not any(same(i, j) for i in distinct for j in distinct if i < j)
    for i, g in enumerate(result.grasps[len(distinct):], start=len(distinct)):
        assert g.duplicate_of <= len(distinct) and same(g.duplicate_of - 1, i)
