"""Which links close onto the object, and which would take the grip from the contact surfaces
(isf.Gripper.closing_joints_of_links, isf.quality.closing.closing_obstructions), against the
bundled URDFs' joint trees read by hand."""

from dataclasses import replace

import numpy as np
import pytest

import isf
from isf.gripper.loading import load_gripper
from isf.quality import quality_rank_key
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


def _depths(gripper, **depths) -> dict[str, float]:
    return {link: depths.get(link, 0.0) for link in gripper.closing_joints_of_links()}


@pytest.fixture(scope="module")
def stiff_hand(hand) -> isf.Gripper:
    """three-finger whose distal joints hold while the proximal ones close: each fingertip is
    then moved by its proximal joint alone, which its proximal link also moves."""
    return replace(hand, closing={**hand.closing, **{f"f{k}_distal_joint": 0.0 for k in range(3)}})


@pytest.mark.parametrize("depths", [
    {"f0_proximal": 1.0e-3, "f0_distal": 0.5e-3},
    {"f1_proximal": 0.2e-3},
    {"palm": 1.5e-3},
])
def test_a_link_that_leaves_a_joint_free_obstructs_nothing(hand, depths):
    """A proximal phalanx that meets the object first stalls its own joint; the distal joint
    still presses the fingertip. The palm does not close."""
    assert closing_obstructions(hand, hand.q_initial, _depths(hand, **depths)) == ()


@pytest.mark.parametrize("depths, expected", [
    # deeper than the fingertip it can stop: the finger meets the object there
    ({"f0_proximal": 1.0e-3, "f0_distal": 0.5e-3}, ("f0_proximal",)),
    ({"f1_proximal": 0.2e-3}, ("f1_proximal",)),
    # as deep as its fingertip (within OBSTRUCTION_MARGIN), shallower, or deeper only than
    # another finger's fingertip, which it cannot stop: no
    ({"f0_proximal": 1.0e-3, "f0_distal": 1.0e-3}, ()),
    ({"f0_proximal": 1.05e-3, "f0_distal": 1.0e-3}, ()),
    ({"f0_proximal": 1.0e-3, "f0_distal": 1.5e-3, "f1_distal": 0.0}, ()),
    ({"palm": 1.5e-3}, ()),
    ({}, ()),
    ({"f0_proximal": 1e-3, "f2_proximal": 2e-3, "f2_distal": 1e-3}, ("f0_proximal", "f2_proximal")),
])
def test_obstructions_by_hand(stiff_hand, depths, expected):
    q = stiff_hand.q_initial
    assert closing_obstructions(stiff_hand, q, _depths(stiff_hand, **depths)) == expected


def test_the_margin_is_how_much_deeper(stiff_hand):
    depths = _depths(stiff_hand, f0_proximal=1.3e-3, f0_distal=1.0e-3)
    q = stiff_hand.q_initial
    assert closing_obstructions(stiff_hand, q, depths, margin=0.2e-3) == ("f0_proximal",)
    assert closing_obstructions(stiff_hand, q, depths, margin=0.4e-3) == ()


def test_robotiq_knuckles_can_stop_both_pads(tmp_path):
    """The vendor Robotiq 2F-85: one actuated joint drives both fingers and their knuckles
    through five mimic joints, so a knuckle deeper than both pads takes the grip."""
    from test_vendor_grippers import tagged_vendor_gripper

    path, package_dirs = tagged_vendor_gripper("robotiq-2f-85", tmp_path)
    robotiq = load_gripper(path, package_dirs=package_dirs)
    pads = {"left_inner_finger_pad": 0.5e-3, "right_inner_finger_pad": 0.8e-3}
    assert set(robotiq.contact_links) == set(pads)
    q = robotiq.q_initial
    knuckle = _depths(robotiq, **pads, left_inner_knuckle=1.2e-3, base_link=2e-3)
    assert closing_obstructions(robotiq, q, knuckle) == ("left_inner_knuckle",)
    level = _depths(robotiq, **pads, right_inner_knuckle=0.85e-3)
    assert closing_obstructions(robotiq, q, level) == ()


def test_planned_grasps_carry_their_obstructions(hand):
    """Each valid grasp of a quality plan carries what closing_obstructions says of its
    collision report's depths (None for the others); an obstructed grasp ranks after every
    unobstructed one, whatever its quality."""
    result = isf.plan(hand, isf.open_object("shape:cylinder"), samples=12, seed=0, diversity=None)
    valid = [g for g in result.grasps if g.valid]
    assert len(valid) >= 2
    assert all(g.closing_obstructed_by is None for g in result.grasps if not g.valid)
    for g in valid:
        assert g.closing_obstructed_by == closing_obstructions(hand, g.q, g.collision.link_depths)
        assert set(g.collision.link_depths) == set(hand.closing_joints_of_links())
    best, worst = valid[0], valid[-1]
    assert quality_rank_key(best.quality, best.fit.mean_distance) < \
        quality_rank_key(worst.quality, worst.fit.mean_distance)
    assert quality_rank_key(best.quality, best.fit.mean_distance, closing_obstructed=True) > \
        quality_rank_key(worst.quality, worst.fit.mean_distance)
