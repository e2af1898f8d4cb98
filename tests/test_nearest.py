"""The compiled k-d tree answers exactly what a brute-force search and scipy's cKDTree answer."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from isf.nearest import NearestPoints


def _brute_force(points, queries):
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    return np.sqrt(d2.min(axis=1)), d2.argmin(axis=1)  # argmin: the lowest index among ties


@pytest.mark.parametrize("n_points", [1, 2, 7, 9, 100, 3000])
def test_matches_brute_force_and_ckdtree(n_points):
    rng = np.random.default_rng(n_points)
    points = rng.normal(size=(n_points, 3)) * [1.0, 0.3, 0.01]  # flat, anisotropic cloud
    queries = np.concatenate([rng.normal(size=(300, 3)), 50.0 * rng.normal(size=(20, 3))])
    distance, index = NearestPoints(points).query(queries)
    expected_distance, expected_index = _brute_force(points, queries)
    np.testing.assert_allclose(distance, expected_distance, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(index, expected_index)
    np.testing.assert_array_equal(distance, cKDTree(points).query(queries)[0])


def test_ties_give_the_lowest_index():
    rng = np.random.default_rng(3)
    grid = np.stack(np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    points = np.concatenate([grid, grid])  # every point twice
    points = points[rng.permutation(len(points))]
    queries = grid[rng.integers(len(grid), size=200)] + rng.choice([0.0, 0.5], size=(200, 3))
    distance, index = NearestPoints(points).query(queries)
    expected_distance, expected_index = _brute_force(points, queries)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)


def test_guesses_never_change_the_answer():
    rng = np.random.default_rng(5)
    points = rng.uniform(size=(2000, 3))
    queries = rng.uniform(-0.2, 1.2, size=(500, 3))
    search = NearestPoints(points)
    expected = search.query(queries)
    for guess in (rng.integers(len(points), size=500), expected[1], np.full(500, -1)):
        distance, index = search.query(queries, guess)
        np.testing.assert_array_equal(distance, expected[0])
        np.testing.assert_array_equal(index, expected[1])


def test_identical_points_and_empty_queries():
    search = NearestPoints(np.ones((50, 3)))
    distance, index = search.query(np.zeros((4, 3)))
    np.testing.assert_allclose(distance, np.sqrt(3.0))
    np.testing.assert_array_equal(index, 0)
    distance, index = search.query(np.empty((0, 3)))
    assert distance.shape == index.shape == (0,)


def test_refuses_a_bad_point_set():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        NearestPoints(np.empty((0, 3)))
