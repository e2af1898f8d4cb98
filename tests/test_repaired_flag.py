"""``Grasp.repaired`` says which grasps are the collision repair of a fit, not the fit itself.

The uniform sampler ignores outcomes, so a plan with and without the repair fits the same samples:
the plan without the repair is the independent record of what each fit was.
"""

import numpy as np

import isf


def test_repaired_grasps_are_the_ones_the_repair_changed(hand, hand_cylinder):
    with_repair = isf.plan(hand, hand_cylinder, samples=12, sampler="uniform", seed=3)
    fits = {g.sample_index: g for g in isf.plan(hand, hand_cylinder, samples=12,
                                                  sampler="uniform", seed=3,
                                                  repair_collisions=False).grasps}
    repaired = [g for g in with_repair.grasps if g.repaired]
    assert repaired, "no sample needed a repair: choose another seed"
    for grasp in with_repair.grasps:
        fit = fits[grasp.sample_index]
        if grasp.repaired:
            assert grasp.collision_free and not fit.collision_free
            assert not np.allclose(grasp.T_object_gripper, fit.T_object_gripper)
            # the history is the fit's: it ends where the fit ended, not at the repaired grasp
            np.testing.assert_allclose(grasp.fit.history[-1].q, fit.q)
        else:
            np.testing.assert_array_equal(grasp.T_object_gripper, fit.T_object_gripper)
            np.testing.assert_array_equal(grasp.q, fit.q)
