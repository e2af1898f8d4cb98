"""Which links close onto the object, and which would take the grip from the contact surfaces
(isf.Gripper.closing_joints_of_links, isf.quality.closing.closing_obstructions), against the
bundled URDFs' joint trees read by hand."""

from dataclasses import replace

import numpy as np
import pytest

import isf
from isf.gripper.loading import load_gripper
from isf.quality.closing import closing_obstructions


@pytest.fixture(scope="module")
def hand() -> isf.Gripper:
    """three-finger: palm, then per finger k a proximal link (joint fk_proximal_joint) and a
    distal link carrying the contact surface (joint fk_distal_joint)."""
    return isf.load_gripper("three-finger")


def test_closing_joints_follow_the_joint_tree(hand):
    moved = hand.closing_joints_of_links()
    assert moved["palm"] == frozenset()
    for k in range(3):
        assert moved[f"f{k}_proximal"] == {f"f{k}_proximal_joint"}
        assert moved[f"f{k}_distal"] == {f"f{k}_proximal_joint", f"f{k}_distal_joint"}
    held = replace(hand, closing={**hand.closing, "f0_proximal_joint": 0.0})
    assert held.closing_joints_of_links()["f0_proximal"] == frozenset()
    assert held.closing_joints_of_links()["f0_distal"] == {"f0_distal_joint"}


@pytest.mark.parametrize("name", ["three-finger", "flat-parallel", "robotiq-2f-85", "allegro-right"])
def test_closing_joints_are_those_that_move_the_link(name, tmp_path):
    """Against forward kinematics: a link is moved by actuated joint j when its pose changes
    as q_j alone changes (the Robotiq's linkage through five mimic joints, the Allegro hand's
    suggested closing signs, some of which hold)."""
    from test_vendor_grippers import tagged_vendor_gripper

    if name in ("three-finger", "flat-parallel"):
        gripper = isf.load_gripper(name)
    else:
        path, package_dirs = tagged_vendor_gripper(name, tmp_path)
        gripper = load_gripper(path, package_dirs=package_dirs)
    q = (gripper.lower + gripper.upper) / 2
    signs = gripper.closing_signs(q)
    poses = gripper.link_poses(q)
    moved = gripper.closing_joints_of_links(q)
    assert set(moved) == set(poses)
    for j, joint in enumerate(gripper.joint_names):
        step = q.copy()
        step[j] += 1e-4
        turned = gripper.link_poses(step)
        for link, T in poses.items():
            moves = not np.allclose(turned[link], T, atol=1e-9)
            assert (joint in moved[link]) == (moves and signs[j] != 0), (link, joint)
    if name == "allegro-right":
        assert 0 in signs  # some joints hold, so the check above covers them


def test_a_mimic_finger_closes_with_its_leader():
    jaw = isf.load_gripper("flat-parallel")  # right_finger_joint mimics left_finger_joint
    moved = jaw.closing_joints_of_links()
    assert moved["left_finger"] == moved["right_finger"] == {"left_finger_joint"}
    assert moved["palm"] == frozenset()
    assert list(jaw.closing_signs()) == [jaw.closing["left_finger_joint"]]


def _depths(hand, **depths) -> dict[str, float]:
    return {link: depths.get(link, 0.0) for link in hand.closing_joints_of_links()}


@pytest.mark.parametrize("depths, expected", [
    # a proximal link deeper than its own finger's fingertip: the finger meets the object there
    ({"f0_proximal": 1.0e-3, "f0_distal": 0.5e-3}, ("f0_proximal",)),
    ({"f1_proximal": 0.2e-3}, ("f1_proximal",)),
    # as deep or shallower than its fingertip, or deeper only than another finger's: no
    ({"f0_proximal": 1.0e-3, "f0_distal": 1.0e-3}, ()),
    ({"f0_proximal": 1.05e-3, "f0_distal": 1.0e-3}, ()),  # within OBSTRUCTION_MARGIN
    ({"f0_proximal": 1.0e-3, "f0_distal": 1.5e-3, "f1_distal": 0.0}, ()),
    # the palm does not close: it touches or not, whatever its depth
    ({"palm": 1.5e-3}, ()),
    ({}, ()),
    ({"f0_proximal": 1e-3, "f2_proximal": 2e-3, "f2_distal": 1e-3}, ("f0_proximal", "f2_proximal")),
])
def test_obstructions_by_hand(hand, depths, expected):
    q = hand.q_initial
    assert closing_obstructions(hand, q, _depths(hand, **depths)) == expected


def test_the_margin_is_how_much_deeper(hand):
    depths = _depths(hand, f0_proximal=1.3e-3, f0_distal=1.0e-3)
    assert closing_obstructions(hand, hand.q_initial, depths, margin=0.2e-3) == ("f0_proximal",)
    assert closing_obstructions(hand, hand.q_initial, depths, margin=0.4e-3) == ()


def test_a_link_that_holds_still_obstructs_nothing(hand):
    depths = _depths(hand, f0_proximal=1e-3)
    held = replace(hand, closing={**hand.closing, "f0_proximal_joint": 0.0})
    assert closing_obstructions(hand, hand.q_initial, depths) == ("f0_proximal",)
    assert closing_obstructions(held, held.q_initial, depths) == ()


def test_planned_grasps_carry_their_obstructions(hand):
    """Each valid grasp of a quality plan carries what closing_obstructions says of its
    collision report's depths; a grasp with obstructions ranks after every one without."""
    result = isf.plan(hand, isf.open_object("shape:cylinder"), samples=12, seed=0, diversity=None)
    valid = [g for g in result.grasps if g.valid]
    assert valid and all(g.closing_obstructed_by is not None for g in valid)
    assert all(g.closing_obstructed_by is None for g in result.grasps if not g.valid)
    for g in valid:
        assert g.closing_obstructed_by == closing_obstructions(hand, g.q, g.collision.link_depths)
    flags = [bool(g.closing_obstructed_by) for g in valid]
    assert flags == sorted(flags)
    assert np.all([set(g.collision.link_depths) >= {"palm", "f0_distal"} for g in valid])
