"""The compiled k-d tree answers exactly what a brute-force search and scipy's cKDTree answer."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from isf.nearest import NearestPoints


def _brute_force(points, queries):
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    return np.sqrt(d2.min(axis=1)), d2.argmin(axis=1)  # argmin: the lowest index among ties


@pytest.mark.parametrize("leaf_size", [1, 8, 32])
@pytest.mark.parametrize("n_points", [1, 2, 7, 9, 100, 3000])
def test_matches_brute_force_and_ckdtree(n_points, leaf_size):
    rng = np.random.default_rng(n_points)
    points = rng.normal(size=(n_points, 3)) * [1.0, 0.3, 0.01]  # flat, anisotropic cloud
    queries = np.concatenate([rng.normal(size=(300, 3)), 50.0 * rng.normal(size=(20, 3))])
    distance, index = NearestPoints(points, leaf_size=leaf_size).query(queries)
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


def test_refuses_bad_guesses():
    search = NearestPoints(np.zeros((5, 3)))
    for guess in ([5, 0], [-2, 0], [0]):
        with pytest.raises(ValueError, match="one index in"):
            search.query(np.zeros((2, 3)), np.array(guess))


def test_refuses_a_bad_point_set():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        NearestPoints(np.empty((0, 3)))


def _brute_force_k(points, queries, k):
    """The k least (squared distance, index) pairs per query, in that order."""
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    rank = np.lexsort((np.broadcast_to(np.arange(len(points)), d2.shape), d2), axis=1)[:, :k]
    return np.sqrt(np.take_along_axis(d2, rank, axis=1)), rank


def _clouds(rng):
    """Point clouds (N, 3) with their queries (M, 3): random, anisotropic, duplicated, far queries."""
    blob = rng.normal(size=(800, 3))
    flat = rng.normal(size=(1500, 3)) * [1.0, 0.3, 0.001]
    grid = np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    doubled = np.concatenate([grid, grid, grid[:40]])[rng.permutation(2 * len(grid) + 40)]
    near = rng.normal(size=(200, 3))
    return {
        "random": (blob, near),
        "anisotropic": (flat, near),
        "duplicated": (doubled, grid[rng.integers(len(grid), size=200)] + rng.choice([0.0, 0.5], size=(200, 3))),
        "far queries": (blob, 100.0 * rng.normal(size=(100, 3))),
    }


@pytest.mark.parametrize("k", [1, 2, 6, 20])
@pytest.mark.parametrize("cloud", ["random", "anisotropic", "duplicated", "far queries"])
def test_k_nearest_match_brute_force_and_ckdtree(cloud, k):
    points, queries = _clouds(np.random.default_rng(11))[cloud]
    distance, index = NearestPoints(points).query_k(queries, k)
    assert distance.shape == index.shape == (len(queries), k)
    expected_distance, expected_index = _brute_force_k(points, queries, k)
    np.testing.assert_allclose(distance, expected_distance, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(index, expected_index)  # nearest first, ties by lower index
    # the distances of the neighbours: bit for bit what scipy reports
    np.testing.assert_array_equal(distance, cKDTree(points).query(queries, k=k)[0].reshape(len(queries), k))
    np.testing.assert_array_equal(distance, np.sqrt(((queries[:, None] - points[index]) ** 2).sum(axis=2)))


def test_k_nearest_agrees_with_the_nearest_query():
    rng = np.random.default_rng(2)
    points = rng.normal(size=(1000, 3)) * [1.0, 0.2, 0.05]
    queries = rng.normal(size=(400, 3))
    search = NearestPoints(points)
    distance, index = search.query_k(queries, 1)
    first = search.query(queries)
    np.testing.assert_array_equal(distance[:, 0], first[0])
    np.testing.assert_array_equal(index[:, 0], first[1])


@pytest.mark.parametrize("n_points", [1, 3, 9])
def test_k_beyond_the_point_count_pads_like_ckdtree(n_points):
    rng = np.random.default_rng(n_points)
    points, queries = rng.normal(size=(n_points, 3)), rng.normal(size=(50, 3))
    distance, index = NearestPoints(points).query_k(queries, 12)
    expected_distance, expected_index = cKDTree(points).query(queries, k=12)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)
    assert np.all(np.isinf(distance[:, n_points:])) and np.all(index[:, n_points:] == n_points)
    np.testing.assert_array_equal(index[:, :n_points], _brute_force_k(points, queries, n_points)[1])


def test_k_nearest_of_no_queries_and_bad_k():
    search = NearestPoints(np.eye(3))
    distance, index = search.query_k(np.empty((0, 3)), 2)
    assert distance.shape == index.shape == (0, 2)
    for k in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="positive integer"):
            search.query_k(np.zeros((1, 3)), k)


@pytest.mark.parametrize("radius", [0.05, 0.3, 2.0])
def test_query_within_a_radius_matches_brute_force(radius):
    rng = np.random.default_rng(7)
    points = rng.normal(size=(500, 3)) * [1.0, 0.5, 0.05]
    points = np.concatenate([points, points[:50]])  # ties: the lowest index must win
    walk = np.cumsum(rng.normal(scale=0.05, size=(200, 3)), axis=0)  # runs of neighbours
    queries = np.concatenate([walk, rng.normal(size=(200, 3)) * 3.0, points[:20]])
    distance, index = NearestPoints(points).query_within(queries, radius)
    expected_distance, expected_index = _brute_force(points, queries)
    inside = expected_distance < radius
    assert inside.any() and not inside.all()
    np.testing.assert_array_equal(index[inside], expected_index[inside])
    np.testing.assert_allclose(distance[inside], expected_distance[inside], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(index[~inside], -1)
    assert np.all(np.isinf(distance[~inside]))


def test_query_within_refuses_a_bad_radius():
    with pytest.raises(ValueError, match="radius"):
        NearestPoints(np.zeros((3, 3))).query_within(np.zeros((1, 3)), 0.0)


@pytest.mark.parametrize("leaf_size", [0, -3, 2.5, True])
def test_refuses_a_bad_leaf_size(leaf_size):
    with pytest.raises(ValueError, match="leaf_size"):
        NearestPoints(np.zeros((3, 3)), leaf_size=leaf_size)
