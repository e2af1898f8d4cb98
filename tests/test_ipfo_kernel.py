"""The compiled IPFO loop pauses for OSQP finger steps and for Pinocchio kinematics, and resumes."""

import numpy as np
import pytest
from _builders import random_rotation

import isf
import isf.fitting._box_qp
from isf.fitting._finger_step import FingerStepQP
from isf.fitting._ipfo import ipfo
from isf.fitting.reference import PairBatch
from isf.fitting.segments import Segments
from isf.se3 import make_transform


@pytest.fixture(scope="module")
def case():
    """Pairs of 6 fits of the three-finger hand: its pads' points, moved by a small random
    palm motion and joint change, matched to where they were (a fit IPFO can undo)."""
    hand = isf.load_gripper("three-finger")
    rng = np.random.default_rng(4)
    counts = np.array([60, 45, 80, 30, 70, 50])
    seg = Segments.from_counts(counts)
    index = np.concatenate([np.sort(rng.choice(hand.n_points, c, replace=False)) for c in counts])
    q_true = rng.uniform(hand.lower + 0.2, hand.upper - 0.2, (len(counts), hand.n_joints))
    T_true = np.stack([make_transform(random_rotation(rng, 1.0), rng.normal(scale=0.05, size=3))
                       for _ in counts])
    links = hand.link_kinematics_many(q_true)
    targets, normals = [], []
    for b, s in enumerate(seg.slices()):
        k = hand.point_link[index[s]]
        R = T_true[b, :3, :3] @ links.rotations[b, k]
        targets.append(np.einsum("kij,kj->ki", R, hand.points_link[index[s]])
                       + links.positions[b, k] @ T_true[b, :3, :3].T + T_true[b, :3, 3])
        normals.append(-np.einsum("kij,kj->ki", R, hand.normals_link[index[s]]))
    pairs = PairBatch(hand, seg, index, np.concatenate(targets), np.concatenate(normals))
    T0 = np.stack([make_transform(random_rotation(rng, 0.05) @ T[:3, :3], T[:3, 3] + rng.normal(scale=0.003, size=3))
                   for T in T_true])
    q0 = np.clip(q_true + rng.normal(scale=0.1, size=q_true.shape), hand.lower, hand.upper)
    return hand, pairs, T0, q0


def _run(hand, pairs, T0, q0):
    qps = [FingerStepQP(hand.n_joints, isf.FitConfig().finger_damping) for _ in range(len(T0))]
    return ipfo(pairs, T0, q0, qps, isf.FitConfig())


def test_pausing_for_kinematics_changes_no_number(case, monkeypatch):
    hand, pairs, T0, q0 = case
    compiled = _run(hand, pairs, T0, q0)
    assert max(len(e) for e in compiled.errors) >= 2  # several alternations were kept
    monkeypatch.setattr(hand, "_chain", None)  # every alternation now asks Python (Pinocchio)
    paused = _run(hand, pairs, T0, q0)
    # Pinocchio and the compiled chain agree bit for bit on this model (tests/test_chain.py)
    np.testing.assert_array_equal(paused.T_object_gripper, compiled.T_object_gripper)
    np.testing.assert_array_equal(paused.q, compiled.q)
    assert paused.errors == compiled.errors


def test_uncertified_finger_steps_resume_with_osqp(case, monkeypatch):
    hand, pairs, T0, q0 = case
    exact = _run(hand, pairs, T0, q0)
    calls = {"osqp": 0}
    solve_normal = FingerStepQP.solve_normal

    def counting(self, *args):
        calls["osqp"] += 1
        return solve_normal(self, *args)

    monkeypatch.setattr(FingerStepQP, "solve_normal", counting)
    monkeypatch.setattr(isf.fitting._box_qp, "MAX_ROUNDS", 0)  # no step certified: all go to OSQP
    osqp = _run(hand, pairs, T0, q0)
    assert calls["osqp"] >= len(T0)
    # the same QPs solved by OSQP instead of the active set: the same fits to OSQP's accuracy
    # (a step resumed in the wrong alternation would move joints by up to 0.3 rad)
    np.testing.assert_allclose(osqp.q, exact.q, atol=2e-5)
    np.testing.assert_allclose(osqp.T_object_gripper, exact.T_object_gripper, atol=2e-5)
    np.testing.assert_allclose(osqp.error, exact.error, rtol=1e-3, atol=1e-12)
    # both pauses in every alternation (OSQP, then Pinocchio): the same numbers again
    monkeypatch.setattr(hand, "_chain", None)
    both = _run(hand, pairs, T0, q0)
    np.testing.assert_array_equal(both.q, osqp.q)
    np.testing.assert_array_equal(both.T_object_gripper, osqp.T_object_gripper)
    assert both.errors == osqp.errors
