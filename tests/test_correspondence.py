"""Correspondence filters: outliers (per fit or per contact surface), duplicates, normals."""

import numpy as np

import isf
from isf.fitting.correspondence import match_many
from isf.fitting.segments import Segments


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


def _reference_filter(dist, target, compatible, groups, fits, factor, floor):
    """The filters of match_many written plainly: np.median per group, then per fit and
    target the nearest pair (the first of equally near ones)."""
    keep = []
    for s in groups.slices():
        threshold = max(factor * np.median(dist[s]), floor)
        keep += [i for i in range(s.start, s.stop) if dist[i] <= threshold and compatible[i]]
    best = {}
    for i in keep:
        key = (fits.ids[i], target[i])
        if key not in best or dist[i] < dist[best[key]]:
            best[key] = i
    return sorted(best.values())


def test_filters_equal_a_plain_reference():
    plane = _plane(n=9)  # 81 object points: many contact points share a target
    rng = np.random.default_rng(0)
    for trial in range(30):
        counts = rng.integers(1, 30, rng.integers(1, 6))
        fits = Segments.from_counts(counts)
        points = np.c_[rng.uniform(-0.025, 0.025, (counts.sum(), 2)), rng.exponential(0.004, counts.sum())]
        points = np.round(points, 3)
        copies = rng.integers(0, len(points), len(points) // 3)
        points[copies] = points[np.maximum(copies - 1, 0)]  # exact ties (same fit, mostly)
        normals = rng.normal(size=points.shape)
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        split = rng.integers(0, 2, counts.sum())  # two surfaces per fit
        groups = Segments.runs(split, fits.ids)
        dist, target = plane.nearest(points)
        compatible = normals @ [0.0, 0.0, 1.0] <= -np.cos(2.0)
        expected = _reference_filter(dist, target, compatible, groups, fits, 2.0, 0.002)
        pairs = match_many(plane, points, fits, outlier_factor=2.0, outlier_floor=0.002, reject_duplicates=True,
                           normals=normals, max_normal_angle=2.0, outlier_groups=groups)
        assert pairs.source.tolist() == expected, trial
        np.testing.assert_array_equal(pairs.target, target[expected])


def test_outlier_threshold_equals_numpy_median_with_ties_and_either_branch():
    """The counting shortcut (floor settles it) and the selection both give exactly
    max(factor * np.median, floor), on distances with many equal values."""
    from isf.fitting.correspondence import outlier_threshold

    rng = np.random.default_rng(3)
    branches = set()
    for trial in range(3000):
        n = int(rng.integers(0, 80))
        kind = trial % 3
        if kind == 0:
            dist = rng.exponential(0.003, n)
        elif kind == 1:
            dist = np.round(rng.exponential(0.003, n), 4)  # ties
        else:
            dist = rng.choice([0.001, 0.0016, 0.0017, 0.01], n)  # ties across the floor / factor
        factor, floor = float(rng.choice([2.0, 3.0])), float(rng.choice([0.0, 0.002, 0.005]))
        expected = floor if n == 0 else max(factor * np.median(dist), floor)
        padded = np.r_[rng.uniform(size=3), dist, rng.uniform(size=2)]  # a group inside an array
        assert outlier_threshold(padded, 3, 3 + n, factor, floor, np.empty(n + 1)) == expected, trial
        if n:
            branches.add(bool((factor * dist <= floor).sum() > n // 2))
    assert branches == {True, False}


def test_select_returns_the_kth_value_and_partitions_around_it():
    from isf.fitting.correspondence import select

    rng = np.random.default_rng(4)
    for trial in range(2000):
        n = int(rng.integers(1, 60))
        values = np.round(rng.normal(size=n), int(rng.integers(0, 3)))  # ties for few decimals
        k = int(rng.integers(0, n))
        work = values.copy()
        kth = select(work, n, k)
        assert kth == np.sort(values)[k], trial
        assert (work[:k] <= kth).all() and (work[k + 1:] >= kth).all()
        np.testing.assert_array_equal(np.sort(work), np.sort(values))
