"""Correspondence filters: outliers (per fit or per contact surface), duplicates, normals."""

import numpy as np

import isf
from isf.correspondence import match_many
from isf.segments import Segments


def _plane(n=41):
    """A 40 x 40 mm plane z = 0 sampled every 1 mm, normals +z."""
    x, y = np.meshgrid(np.linspace(-0.02, 0.02, n), np.linspace(-0.02, 0.02, n))
    points = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    return isf.load_object(np.c_[points, np.tile([0.0, 0.0, 1.0], (len(points), 1))], name="plane")


def test_a_far_surface_is_an_outlier_of_the_fit_but_not_of_its_own_group():
    plane = _plane()
    rng = np.random.default_rng(0)
    near = np.c_[rng.uniform(-0.015, 0.015, (30, 2)), np.full(30, 0.0005)]  # a pad 0.5 mm above
    far = np.c_[rng.uniform(-0.015, 0.015, (10, 2)), np.full(10, 0.012)]  # a fingertip 12 mm away
    points = np.concatenate([near, far])
    one_fit = Segments.single(len(points))
    kwargs = dict(outlier_factor=3.0, outlier_floor=0.005, reject_duplicates=False)
    by_fit = match_many(plane, points, one_fit, **kwargs)
    assert set(by_fit.source.tolist()) == set(range(30))  # 12 mm > max(3 x median, 5 mm)
    per_surface = Segments(np.r_[np.zeros(30, int), np.ones(10, int)])
    by_surface = match_many(plane, points, one_fit, outlier_groups=per_surface, **kwargs)
    assert set(by_surface.source.tolist()) == set(range(40))


def test_duplicates_are_rejected_within_a_fit_not_across_fits():
    plane = _plane()
    p = np.array([[0.0, 0.0, 0.001], [0.0, 0.0, 0.002]])  # both nearest to the origin sample
    points = np.concatenate([p, p])
    fits = Segments(np.array([0, 0, 1, 1]))
    pairs = match_many(plane, points, fits, outlier_factor=3.0, outlier_floor=0.005, reject_duplicates=True)
    assert pairs.source.tolist() == [0, 2]  # the closer of each fit's two


def test_group_medians_equal_numpy_medians():
    from isf.correspondence import _group_medians

    rng = np.random.default_rng(0)
    for _ in range(50):
        counts = rng.integers(1, 40, rng.integers(1, 10))
        groups = Segments.from_counts(counts)
        values = rng.random(counts.sum())
        expected = [np.median(values[s]) for s in groups.slices()]
        np.testing.assert_array_equal(_group_medians(values, groups), expected)
