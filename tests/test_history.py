"""``FitResult.history`` says what the fit did: the start (iteration 0), then per ISF iteration the
palm pose, the joints, the distance, E (summed and per pair) and the stop rule's ratio.

Independent references: the plain-numpy reference fit (:func:`isf.fitting.reference.fit`, its own
correspondences and IPFO) for the start record; the stop rule's displacement ratio recomputed here
from the recorded poses and the gripper's own forward kinematics; the plan without the repair for
the history of repaired grasps.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import isf
from isf.fitting import reference
from isf.se3 import exp_so3, make_transform


def _start(rng, angle=0.3, offset=0.01):
    """A start pose turned by ``angle`` (rad) about a random axis, shifted up to ``offset`` (m)."""
    axis = rng.normal(size=3)
    return make_transform(exp_so3(angle * axis / np.linalg.norm(axis)),
                          rng.uniform(-offset, offset, 3))


def _placed(gripper, record, mask):
    """The contact points ``mask`` at a record's joints and pose, object frame, (P, 3)."""
    points, _ = gripper.contact_points(record.q, mask)
    T = record.T_object_gripper
    return points @ T[:3, :3].T + T[:3, 3]


@pytest.fixture(scope="module")
def cylinder():
    return isf.open_object("shape:cylinder")


@pytest.mark.parametrize("name", ["paper-parallel", "three-finger"])
def test_the_history_starts_at_the_start_pose(name, cylinder):
    """Record 0 is the start: the pose and joints given, on the coarsest level, no IPFO, no
    ratio; its pairs, distance and E are those the reference matches at the start pose."""
    gripper = isf.load_gripper(name)
    rng = np.random.default_rng(5)
    for _ in range(3):
        T0 = _start(rng)
        fit = isf.fit(gripper, cylinder, T0)
        expected = reference.fit(gripper, cylinder, T0)
        start = fit.history[0]
        assert len(fit.history) == fit.iterations + 1 and fit.iterations > 0
        assert (start.level, start.iteration) == (isf.FitConfig().levels - 1, 0)
        np.testing.assert_array_equal(start.T_object_gripper, T0)
        np.testing.assert_array_equal(start.q, gripper.q_initial)
        assert start.ipfo_errors == () and math.isnan(start.displacement_ratio)
        other = expected.history[0]
        assert other.iteration == 0 and start.n_pairs == other.n_pairs
        assert start.mean_distance == pytest.approx(other.mean_distance, rel=1e-9)
        assert start.error == pytest.approx(other.error, rel=1e-9)
        # the first IPFO starts from the start's E and only lowers it
        assert fit.history[1].ipfo_errors[0] <= start.error * (1 + 1e-12)


@pytest.mark.parametrize("name", ["paper-parallel", "three-finger"])
def test_the_records_hold_the_pose_and_the_stop_rule(name, cylinder):
    """Each record's pose and joints place the level's contact points; the ratio of their
    displacement from the level's start, record to record, is the recorded ratio (0 on a
    level's first iteration, whose previous displacement is infinite); the last record is the
    fit's final state and a converged fit's last ratio lies within 1 +- eps0."""
    gripper = isf.load_gripper(name)
    config = isf.FitConfig()
    rng = np.random.default_rng(11)
    for _ in range(3):
        fit = isf.fit(gripper, cylinder, _start(rng))
        records = list(fit.history)
        np.testing.assert_array_equal(records[-1].T_object_gripper, fit.T_object_gripper)
        np.testing.assert_array_equal(records[-1].q, fit.q)
        for h in range(1, len(records)):
            level = records[h].level
            mask = gripper.level_mask(level)
            if records[h - 1].level != level or records[h - 1].iteration == 0:  # level starts
                level_start, previous = _placed(gripper, records[h - 1], mask), np.inf
            displacement = np.linalg.norm(_placed(gripper, records[h], mask) - level_start)
            ratio = 1.0 if displacement <= 1e-12 else displacement / previous
            assert records[h].displacement_ratio == pytest.approx(ratio, rel=1e-6, abs=1e-12)
            previous = displacement
        if fit.converged:
            assert abs(records[-1].displacement_ratio - 1.0) <= config.tolerance


def test_error_per_pair_is_the_sum_over_the_pairs(cylinder):
    """E per pair is E summed divided by the pairs, record by record and for the result, and the
    history's array attributes hold the records' numbers."""
    gripper = isf.load_gripper("paper-parallel")
    fit = isf.fit(gripper, cylinder, _start(np.random.default_rng(2)))
    history = fit.history
    for h, record in enumerate(history):
        assert record.error_per_pair == pytest.approx(record.error / record.n_pairs, rel=1e-15)
        assert history.error_per_pair[h] == pytest.approx(record.error_per_pair, rel=1e-15)
        assert (history.level[h], history.iteration[h], history.n_pairs[h]) == (
            record.level, record.iteration, record.n_pairs)
        assert history.mean_distance[h] == record.mean_distance
        np.testing.assert_array_equal(history.T_object_gripper[h], record.T_object_gripper)
    assert fit.error_per_pair == pytest.approx(fit.error / fit.n_pairs, rel=1e-15)
    assert repr(history) == f"History({len(history)} records: the start and {fit.iterations} iterations)"


def test_a_fit_that_never_matches_has_no_record(cylinder):
    """A fit that loses contact at its start pose made no iteration and records nothing, as
    the reference does."""
    gripper = isf.load_gripper("paper-parallel")
    config = isf.FitConfig(min_pairs=10**6)
    fit = isf.fit(gripper, cylinder, np.eye(4), config=config)
    expected = reference.fit(gripper, cylinder, np.eye(4), config=config)
    assert fit.status is isf.FitStatus.LOST_CONTACT and fit.iterations == 0
    assert len(fit.history) == 0 == len(expected.history)
    assert fit.history.T_object_gripper.shape == (0, 4, 4)


def test_a_repaired_grasp_keeps_the_fits_history(hand, hand_cylinder):
    """The history of a repaired grasp is the fit's: it ends at the pose and joints where the
    same fit ends without the repair, not at the repaired grasp; an unrepaired grasp's history
    ends at the grasp."""
    kwargs = {"samples": 12, "sampler": "uniform", "seed": 3, "centring": False}
    with_repair = isf.plan(hand, hand_cylinder, **kwargs)
    fits = {g.sample_index: g for g in isf.plan(hand, hand_cylinder, repair_collisions=False,
                                                  **kwargs).grasps}
    assert any(g.repaired for g in with_repair.grasps)
    for grasp in with_repair.grasps:
        last = grasp.fit.history[-1]
        fit = fits[grasp.sample_index]
        np.testing.assert_array_equal(last.T_object_gripper, fit.fit.T_object_gripper)
        np.testing.assert_array_equal(last.q, fit.fit.q)
        if grasp.repaired:
            assert not np.array_equal(last.T_object_gripper, grasp.T_object_gripper)
        else:
            np.testing.assert_array_equal(last.T_object_gripper, grasp.T_object_gripper)
