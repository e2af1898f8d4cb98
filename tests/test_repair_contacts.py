"""The repair's compiled contact pairs (isf.repair._contacts) are match_many's pairs, with the
surfaces as groups, of the contact points the gripper's kinematics place."""

import numpy as np
import pytest

from isf.fitting.correspondence import match_many
from isf.fitting.segments import Segments
from isf.repair._contacts import contact_pairs
from isf.se3 import exp_so3, make_transform


@pytest.fixture(scope="module")
def hand_and_cylinder(hand, hand_cylinder):
    return hand, hand_cylinder


@pytest.mark.parametrize("max_normal_angle", [1.5, np.pi])
def test_contact_pairs_are_match_many_pairs_at_random_states(hand_and_cylinder, max_normal_angle):
    gripper, obj = hand_and_cylinder
    surfaces = Segments(gripper.point_surface)
    contact = (gripper.point_link.astype(np.int64), gripper.points_link, gripper.normals_link)
    arrays = (obj.points, obj.normals, obj.search.tree)
    cos_limit = -np.cos(max_normal_angle) if max_normal_angle < np.pi else np.inf
    guess = np.full(gripper.n_points, -1, np.int64)  # kept across states, as a repairer does
    rng = np.random.default_rng(0)
    kept_some = dropped_some = False
    for _ in range(15):
        T = make_transform(exp_so3(rng.normal(size=3)),
                           obj.points.mean(axis=0) + rng.normal(scale=0.03, size=3))
        q = rng.uniform(gripper.lower, gripper.upper)
        links = gripper.link_kinematics(q)
        source, points, target = contact_pairs(T, links.rotations, links.positions, contact,
                                               surfaces.starts, arrays, guess, 3.0, 0.004,
                                               cos_limit)
        gripper_points, normals = gripper.contact_points(q)
        expected_points = gripper_points @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(points, expected_points, rtol=0, atol=1e-15)
        pairs = match_many(obj, points, surfaces, outlier_factor=3.0, outlier_floor=0.004,
                           reject_duplicates=True, normals=normals @ T[:3, :3].T,
                           max_normal_angle=max_normal_angle)
        np.testing.assert_array_equal(source, pairs.source)
        np.testing.assert_array_equal(target[source], pairs.target)
        _, fresh = obj.nearest(points)
        np.testing.assert_array_equal(target, fresh)  # the guesses never change an answer
        kept_some |= len(source) > 0
        dropped_some |= len(source) < gripper.n_points
    assert kept_some and dropped_some
