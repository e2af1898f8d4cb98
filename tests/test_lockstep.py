"""The compiled lockstep engine: one round against the Python pieces, and its pauses for Python
(its searches from each contact point's last answer: ``tests/test_nearest.py``)."""

import numpy as np
import pytest
from _builders import random_rotation

import isf
from isf.config import FitConfig
from isf.fitting._finger_step import FingerStepQP
from isf.fitting._ipfo import ipfo
from isf.fitting.correspondence import match_many
from isf.fitting.reference import PairBatch
from isf.fitting.segments import Segments
from isf.se3 import make_transform


def _starts(rng, gripper, n):
    """Grasp-like starts: the gripper above the cylinder's axis, turned and moved a little."""
    T = make_transform(np.eye(3), [0.0, 0.0, -0.06]) if gripper.name == "paper-parallel" else \
        make_transform(np.eye(3), [0.0, 0.0, -0.05])
    return [make_transform(random_rotation(rng, 0.3), rng.normal(scale=0.003, size=3)) @ T
            for _ in range(n)]


@pytest.mark.parametrize("name", ["paper-parallel", "three-finger"])
def test_one_round_equals_the_correspondences_and_ipfo_of_the_python_pieces(name, cylinder):
    """One ISF iteration of the engine (one level, one iteration) lands where match_many's pairs
    and isf.fitting._ipfo's alternations (the pair-by-pair correspondence filters and the IPFO driver) do."""
    gripper = isf.load_gripper(name)
    config = FitConfig(levels=1, max_iterations=1)
    rng = np.random.default_rng(1)
    starts = _starts(rng, gripper, 4)
    results = isf.fit_many(gripper, cylinder, np.stack(starts), config=config)
    q0 = gripper.q_initial
    for T0, result in zip(starts, results):
        assert result.iterations == 1
        points, normals = gripper.contact_points(q0)
        points, normals = points @ T0[:3, :3].T + T0[:3, 3], normals @ T0[:3, :3].T
        fit = Segments.single(len(points))
        pairs = match_many(cylinder, points, fit, outlier_factor=config.outlier_factor,
                           outlier_floor=config.outlier_floor,
                           reject_duplicates=config.reject_duplicates,
                           normals=normals, max_normal_angle=config.max_normal_angle,
                           outlier_groups=Segments.runs(gripper.point_surface))
        assert result.history[0].n_pairs == len(pairs.source)
        batch = PairBatch(gripper, Segments.single(len(pairs.source)), pairs.source,
                          cylinder.points[pairs.target], cylinder.normals[pairs.target])
        qp = FingerStepQP(gripper.n_joints, config.finger_damping)
        expected = ipfo(batch, T0[None], q0[None], [qp], config)
        np.testing.assert_allclose(result.T_object_gripper, expected.T_object_gripper[0], rtol=0,
                                   atol=1e-12)
        np.testing.assert_allclose(result.q, expected.q[0], rtol=0, atol=1e-12)
        assert result.history[1].ipfo_errors == pytest.approx(expected.errors[0], rel=1e-9)


def test_pausing_for_python_changes_no_number(cylinder, monkeypatch):
    """Fits whose IPFO pauses for Pinocchio in every alternation (joints without compiled
    kinematics) run the rounds through Python and end exactly where the compiled rounds do."""
    hand = isf.load_gripper("three-finger")
    starts = np.stack(_starts(np.random.default_rng(2), hand, 6))
    compiled = isf.fit_many(hand, cylinder, starts)
    monkeypatch.setattr(hand, "_chain", None)
    paused = isf.fit_many(hand, cylinder, starts)
    assert max(r.iterations for r in compiled) > 5
    for a, b in zip(compiled, paused):
        np.testing.assert_array_equal(a.T_object_gripper, b.T_object_gripper)
        np.testing.assert_array_equal(a.q, b.q)
        assert a.iterations == b.iterations and a.status == b.status
        assert [r.ipfo_errors for r in a.history] == [r.ipfo_errors for r in b.history]


def test_slots_are_reused_and_grown():
    """Fits added while others run take freed slots, or new ones; each ends as it would alone."""
    gripper = isf.load_gripper("paper-parallel")
    obj = isf.open_object("shape:cylinder")
    starts = _starts(np.random.default_rng(3), gripper, 20)
    alone = isf.fit_many(gripper, obj, np.stack(starts))
    fitter = isf.fitting.engine.LockstepFitter(gripper, obj)
    results, added = {}, 0
    while len(results) < len(starts):
        while added < len(starts) and fitter.n_active < 3 + added % 11:
            fitter.add(added, starts[added])
            added += 1
        results.update(fitter.advance())
    for k, r in enumerate(alone):
        np.testing.assert_array_equal(results[k].T_object_gripper, r.T_object_gripper)
        assert results[k].iterations == r.iterations


def test_fits_solved_by_osqp_do_not_depend_on_the_fits_before_them(cylinder, monkeypatch):
    """With every finger step sent to OSQP (no step certified by the active set), fits run
    together, one after another in reused slots, and alone end in the same place."""
    monkeypatch.setattr(isf.fitting._box_qp, "MAX_ROUNDS", 0)
    hand = isf.load_gripper("three-finger")
    starts = _starts(np.random.default_rng(4), hand, 5)
    together = isf.fit_many(hand, cylinder, np.stack(starts))
    fitter = isf.fitting.engine.LockstepFitter(hand, cylinder)
    for k, T in enumerate(starts):  # one slot, reused by every fit in turn
        fitter.add(k, T)
        while fitter.n_active:
            (key, result), = fitter.advance()
        alone = isf.fit(hand, cylinder, T)
        for other in (together[k], alone):
            np.testing.assert_array_equal(result.T_object_gripper, other.T_object_gripper)
            np.testing.assert_array_equal(result.q, other.q)


def test_the_history_reads_as_the_records_of_the_kernels_arrays():
    """The records, built when first read, hold the numbers the rounds logged: the start, then
    one per iteration, in order, with each level's iterations counted from 1."""
    gripper = isf.load_gripper("paper-parallel")
    obj = isf.open_object("shape:cylinder")
    result = isf.fit(gripper, obj, T_object_gripper=make_transform(np.eye(3), [0.004, 0.0, 0.002]))
    history = result.history
    assert len(history) == result.iterations + 1 > 1 and repr(history).startswith("History(")
    records = list(history)
    assert all(history[h] is records[h] for h in range(len(history))) and history[-1] is records[-1]
    assert all(a is b for a, b in zip(history[1:3], records[1:3])) and len(history[1:3]) == 2
    assert records[0].iteration == 0 and records[0].ipfo_errors == ()
    records = records[1:]  # the iterations
    levels = [r.level for r in records]
    assert levels == sorted(levels, reverse=True)
    for level in set(levels):
        assert [r.iteration for r in records if r.level == level] == list(
            range(1, levels.count(level) + 1))
    assert all(isinstance(r.level, int) and isinstance(r.n_pairs, int) and r.n_pairs > 0
               and r.q.shape == (gripper.n_joints,) and len(r.ipfo_errors) >= 1 for r in records)
    assert np.isfinite([r.mean_distance for r in records]).all()
    np.testing.assert_array_equal(records[-1].q, result.q)  # the last IPFO's joints are the fit's
