"""Planning on worker threads (``isf.plan(..., workers=W)``): the same grasps as the window
protocol run in one thread with the public pieces, whatever the threads' timing."""

import threading
from collections import deque

import numpy as np
import pytest

import isf
from isf.config import FitConfig
from isf.planning.centring import GraspCentring
from isf.quality import object_properties
from isf.repair.clearance import ClearanceRepair, repair_penetration


@pytest.fixture(scope="module")
def block():
    """A box the size of a hand's grasp: fits often end with a link in it, so repairs run."""
    return isf.open_object("shape:box", scale=3.0, max_points=1500)


def _window_reference(gripper, obj, samples, seed, window, repair_config=None):
    """The protocol of ``workers=W`` (``window`` = 1 for W = 1, else ``SAMPLES_PER_WORKER * W``),
    in one thread, from ``isf.fit``, the collision checker, the repair (with ``repair_config``)
    and the centring: proposals in order with at most ``window`` awaiting
    their outcome, outcomes reported in order. Returns the grasps by sample index and the number
    of repairs that were kept."""
    sampler = isf.get_sampler("regret")
    rng = np.random.default_rng(seed)
    sampler.reset(obj, gripper, rng)
    checker = isf.CollisionChecker(gripper, obj)
    repairer = ClearanceRepair(gripper, obj, repair_config)
    centring = GraspCentring(gripper, obj, object_properties(obj).center_of_mass, checker,
                             FitConfig())
    kept_repairs = 0

    def evaluate(proposal):
        nonlocal kept_repairs
        fit = isf.fit(gripper, obj, proposal.T_object_gripper, proposal.q)
        report = checker.check(fit.T_object_gripper, fit.q)
        if not report.collision_free:
            repaired = repair_penetration(gripper, obj, fit, repairer=repairer)
            again = checker.check(repaired.T_object_gripper, repaired.q)
            if again.collision_free:
                fit, report, kept_repairs = repaired, again, kept_repairs + 1
        centred = centring.centre(fit, report)
        return centred.result, centred.report

    pending, grasps, proposed = deque(), {}, 0
    while pending or proposed < samples:
        limit = sampler.in_flight_limit()
        while proposed < samples and len(pending) < (window if limit is None else
                                                       max(1, min(window, limit))):
            (proposal,) = sampler.propose(1, rng)
            pending.append((proposed, proposal, evaluate(proposal)))
            proposed += 1
        index, proposal, (fit, report) = pending.popleft()
        error = fit.mean_distance if fit.all_surfaces_in_contact else isf.planning.planner.NO_CONTACT_ERROR
        sampler.observe([isf.Outcome(proposal, error=error, collision_free=report.collision_free)])
        grasps[index] = (fit, report)
    return grasps, kept_repairs


def _by_index(result):
    return {g.sample_index: g for g in result.grasps}


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_workers_give_the_window_protocol_grasps(hand, block, workers):
    samples = 9
    window = 1 if workers == 1 else isf.planning.planner.SAMPLES_PER_WORKER * workers
    expected, kept_repairs = _window_reference(hand, block, samples, seed=2, window=window)
    assert kept_repairs >= 1  # the repair path ran and was used
    result = isf.plan(hand, block, samples=samples, seed=2, workers=workers, working_spacing=None)
    assert result.stats.workers == workers and result.stats.samples == samples
    assert sorted(expected) == list(range(samples))
    assert any(g.centred for g in result.grasps)  # the centring path ran and was used
    _assert_same_grasps(result, expected)


def _assert_same_grasps(result, expected):
    """The plan's grasps are the reference's (by sample index), bit for bit."""
    got = _by_index(result)
    assert sorted(got) == sorted(expected)
    for index, (fit, report) in expected.items():
        grasp = got[index]
        np.testing.assert_array_equal(grasp.T_object_gripper, fit.T_object_gripper)
        np.testing.assert_array_equal(grasp.q, fit.q)
        assert grasp.fit.mean_distance == fit.mean_distance
        assert grasp.collision_free == report.collision_free
        assert grasp.collision.penetration == report.penetration


@pytest.mark.parametrize("workers", [1, 2])
def test_a_repair_config_reaches_every_repair(hand, block, workers):
    config = isf.RepairConfig(max_rows=6, iterations=3)
    window = 1 if workers == 1 else isf.planning.planner.SAMPLES_PER_WORKER * workers
    expected, _ = _window_reference(hand, block, 8, seed=2, window=window, repair_config=config)
    default, _ = _window_reference(hand, block, 8, seed=2, window=window)
    # the parameters change some repaired grasp here, so a plan that ignored them would differ
    assert any(not np.array_equal(expected[i][0].T_object_gripper, default[i][0].T_object_gripper)
               for i in expected)
    result = isf.plan(hand, block, samples=8, seed=2, workers=workers, working_spacing=None,
                      repair_collisions=config)
    _assert_same_grasps(result, expected)


@pytest.mark.parametrize("workers, window", [(1, 1), (2, 4), (3, 6)])
def test_the_sampler_hears_each_outcome_at_most_window_minus_one_samples_late(
        hand, block, workers, window):
    """At proposal i the sampler has seen exactly the outcomes of samples 0 .. i - window, in
    order, whatever the threads' timing (a sampler that sets no in-flight limit)."""
    from isf.samplers import UniformSampler

    class Counting(UniformSampler):
        name = "counting"

        def reset(self, obj, gripper, rng):
            super().reset(obj, gripper, rng)
            self.seen_at_proposal, self.observed = [], []

        def propose(self, n, rng):
            self.seen_at_proposal.append(len(self.observed))
            return [isf.Proposal(p.T_object_gripper, p.q, {"index": len(self.seen_at_proposal) - 1})
                    for p in super().propose(n, rng)]

        def observe(self, outcomes):
            self.observed += [o.proposal.record["index"] for o in outcomes]

    sampler, samples = Counting(), 10
    isf.plan(hand, block, samples=samples, seed=3, sampler=sampler, workers=workers)
    assert sampler.observed == list(range(samples))
    assert sampler.seen_at_proposal == [max(0, i - window + 1) for i in range(samples)]


def test_one_worker_is_the_sequential_loop(hand, block):
    a = isf.plan(hand, block, samples=6, seed=5, workers=1)
    b = isf.plan(hand, block, samples=6, seed=5)  # the default: batch_size 1, workers 1
    for ga, gb in zip(a.grasps, b.grasps):
        assert ga.sample_index == gb.sample_index
        np.testing.assert_array_equal(ga.T_object_gripper, gb.T_object_gripper)


def test_progress_is_reported_in_sample_order_from_the_calling_thread(hand, block):
    calls = []

    def progress(done, total, grasp):
        calls.append((done, total, grasp.sample_index, threading.current_thread()))

    isf.plan(hand, block, samples=7, seed=1, workers=2, progress=progress)
    assert [c[:3] for c in calls] == [(i + 1, 7, i) for i in range(7)]
    assert all(c[3] is threading.main_thread() for c in calls)


@pytest.mark.parametrize("kwargs, message", [
    ({"workers": 0}, "workers must be a positive integer"),
    ({"workers": 1.5}, "workers must be a positive integer"),
    ({"workers": 2, "batch_size": 2}, "not both"),
    ({"repair_collisions": "yes"}, "repair_collisions must be True, False or an isf.RepairConfig"),
])
def test_bad_worker_arguments(hand, block, kwargs, message):
    with pytest.raises(isf.InvalidInputError, match=message):
        isf.plan(hand, block, samples=2, **kwargs)


def test_link_poses_from_many_threads_match_one_thread(hand):
    """Pinocchio writes into a Data object: each thread must use its own."""
    rng = np.random.default_rng(0)
    Q = rng.uniform(hand.lower, hand.upper, size=(40, hand.n_joints))
    expected = [hand.link_poses(q) for q in Q]
    failures = []

    def worker(offset):
        for _ in range(20):
            for i in range(offset, len(Q), 2):
                poses = hand.link_poses(Q[i])
                if any(not np.array_equal(poses[k], expected[i][k]) for k in poses):
                    failures.append(i)

    threads = [threading.Thread(target=worker, args=(k,)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures


def test_an_invalid_proposal_fails_the_plan_with_its_error(hand, block):
    """A sampler's bad pose is refused on the worker thread and raised in the caller's, as in the
    sequential loop; the plan stops."""
    from isf.samplers import UniformSampler

    class Reflecting(UniformSampler):
        name = "reflecting"

        def propose(self, n, rng):
            proposals = super().propose(n, rng)
            flip = np.diag([1.0, 1.0, -1.0, 1.0])
            return [isf.Proposal(p.T_object_gripper @ flip, p.q, p.record) for p in proposals]

    for workers in (1, 2):
        with pytest.raises(isf.InvalidInputError, match="not a rigid transform"):
            isf.plan(hand, block, samples=4, sampler=Reflecting(), workers=workers)
