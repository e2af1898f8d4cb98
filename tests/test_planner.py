"""The planner (paper Algorithm 3): ranking, determinism, obstacles, guided sampling."""

import numpy as np
import pytest
import trimesh

import isf


def test_same_seed_same_result(paper_gripper, cylinder):
    a = isf.plan(paper_gripper, cylinder, samples=6, seed=3)
    b = isf.plan(paper_gripper, cylinder, samples=6, seed=3)
    assert [g.sample_index for g in a.grasps] == [g.sample_index for g in b.grasps]
    for ga, gb in zip(a.grasps, b.grasps):
        np.testing.assert_array_equal(ga.T_object_gripper, gb.T_object_gripper)
        np.testing.assert_array_equal(ga.q, gb.q)
    c = isf.plan(paper_gripper, cylinder, samples=6, seed=4)
    assert any(not np.array_equal(x.T_object_gripper, y.T_object_gripper)
               for x, y in zip(a.grasps, c.grasps))


def test_ranking_and_stats(paper_gripper, cylinder):
    result = isf.plan(paper_gripper, cylinder, samples=12, seed=0)
    for duplicates in (False, True):  # distinct grasps first, each part in ranking order
        keys = [g.sort_key() for g in result.grasps if (g.duplicate_of is not None) == duplicates]
        assert keys == sorted(keys)
    flags = [g.duplicate_of is not None for g in result.grasps]
    assert flags == sorted(flags)
    assert result.stats.samples == len(result.grasps) == 12
    assert result.stats.collision_free == sum(g.collision_free for g in result.grasps)
    assert result.stats.collision_free > 0
    best = result.best
    assert best.collision_free and best.fit.mean_distance < 0.2e-3
    assert 2 * best.q[0] == pytest.approx(0.016, abs=0.3e-3)  # the cylinder's diameter
    records = [g.sampler_record for g in result.grasps]
    assert all(set(r) in ({"cluster", "regret"}, {"start"}) for r in records)
    assert sum("start" in r for r in records) == 6  # every second sample (RegretSampler.com_share)


def _lowest_point(gripper, grasp):
    T = grasp.T_object_gripper
    poses = gripper.link_poses(grasp.q)
    heights = [(T @ poses[g.link] @ np.c_[g.vertices, np.ones(len(g.vertices))].T)[2].min()
               for g in gripper.geometries]
    return min(heights)


def test_table_rejects_grasps_below_it():
    """A tall box standing on a table: no collision-free grasp reaches below the table."""
    gripper = isf.load_gripper("flat-parallel")
    box = isf.load_object(trimesh.creation.box(extents=[0.02, 0.015, 0.05]), name="tall box")
    table = isf.Plane.table(-0.025)  # the box's bottom face
    result = isf.plan(gripper, box, samples=20, seed=1, obstacles=[table])
    free = result.collision_free_grasps()
    rejected = [g for g in result.grasps if g.collision.obstacle == "table"]
    assert free and rejected
    for grasp in free:
        assert _lowest_point(gripper, grasp) > -0.025 - 0.002  # tolerance: 2 mm
    for grasp in rejected:
        assert _lowest_point(gripper, grasp) < -0.025 - 0.002


def spheres_and_rod():
    """Five 5 cm spheres (too big for a 3 cm jaw) far apart, and one 16 mm rod that fits the
    grooves."""
    parts = [trimesh.creation.icosphere(subdivisions=3, radius=0.025).apply_translation(
        [0.2 * np.cos(a), 0.2 * np.sin(a), 0.0]) for a in np.linspace(0, 2 * np.pi, 6)[:5]]
    parts.append(trimesh.creation.cylinder(radius=0.008, height=0.05, sections=48))
    return isf.load_object(trimesh.util.concatenate(parts), name="spheres-and-rod")


def test_regret_finds_the_only_good_region_sooner_than_uniform(paper_gripper):
    """Only the rod admits a good fit; measured over several seeds, the bandit gets there sooner."""
    obj = spheres_and_rod()

    def first_good(sampler, seed, samples=16):
        result = isf.plan(paper_gripper, obj, samples=samples, sampler=sampler, seed=seed)
        order = sorted(result.grasps, key=lambda g: g.sample_index)
        good = [g.valid and g.fit.mean_distance < 0.2e-3 for g in order]
        return good.index(True) + 1 if any(good) else samples + 1, sum(good)

    regret = [first_good("regret", seed) for seed in range(4)]
    uniform = [first_good("uniform", seed) for seed in range(4)]
    assert np.mean([r[0] for r in regret]) < np.mean([u[0] for u in uniform])
    assert sum(r[1] for r in regret) > 2 * sum(u[1] for u in uniform)


def test_bad_samples_argument(paper_gripper, cylinder):
    with pytest.raises(isf.InvalidInputError, match="samples"):
        isf.plan(paper_gripper, cylinder, samples=0)
    with pytest.raises(isf.SamplerNotFound, match="regret"):
        isf.plan(paper_gripper, cylinder, samples=1, sampler="no-such-sampler")


@pytest.mark.parametrize("batch_size", [1, 3])
def test_each_sample_is_proposed_fitted_checked_and_observed(paper_gripper, cylinder, batch_size):
    """Algorithm 3's loop, one sample at a time or in lockstep batches: every grasp is the fit
    :func:`isf.fit` makes from its proposal, checked for collisions, and the sampler hears its
    error and collision verdict."""
    from isf.collision.checker import CollisionChecker
    from isf.samplers import UniformSampler

    class Recording(UniformSampler):
        name = "recording"

        def reset(self, obj, gripper, rng):
            super().reset(obj, gripper, rng)
            self.proposals, self.outcomes = [], []

        def propose(self, n, rng):
            proposals = [isf.Proposal(p.T_object_gripper, p.q, {"index": len(self.proposals)})
                         for p in super().propose(n, rng)]
            self.proposals += proposals
            return proposals

        def observe(self, outcomes):
            self.outcomes += outcomes

    sampler = Recording()
    result = isf.plan(paper_gripper, cylinder, samples=5, seed=2, sampler=sampler,
                      batch_size=batch_size, repair_collisions=False, centring=False,
                      working_spacing=None)
    checker = CollisionChecker(paper_gripper, cylinder)
    heard = {o.proposal.record["index"]: o for o in sampler.outcomes}
    assert sorted(heard) == list(range(5))
    for grasp in result.grasps:
        proposal = sampler.proposals[grasp.sample_index]
        alone = isf.fit(paper_gripper, cylinder, proposal.T_object_gripper, proposal.q)
        np.testing.assert_array_equal(grasp.T_object_gripper, alone.T_object_gripper)
        np.testing.assert_array_equal(grasp.q, alone.q)
        report = checker.check(alone.T_object_gripper, alone.q)
        assert grasp.collision_free == report.collision_free
        outcome = heard[grasp.sample_index]
        assert outcome.collision_free == report.collision_free
        if alone.all_surfaces_in_contact:
            assert outcome.error == alone.mean_distance
