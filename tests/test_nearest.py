"""The compiled k-d tree, and the walks on the Delaunay graph, answer exactly what a brute-force
search and scipy's cKDTree answer."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from isf.search._neighbour_graph import neighbour_graph
from isf.search.nearest import NearestPoints, nearest_point, search_scratch

GRAPH = pytest.mark.parametrize("graph", [False, True], ids=["tree", "graph"])


def _brute_force(points, queries):
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    return np.sqrt(d2.min(axis=1)), d2.argmin(axis=1)  # argmin: the lowest index among ties


@GRAPH
@pytest.mark.parametrize("leaf_size", [1, 8, 32])
@pytest.mark.parametrize("n_points", [1, 2, 7, 9, 100, 3000])
def test_matches_brute_force_and_ckdtree(n_points, leaf_size, graph):
    rng = np.random.default_rng(n_points)
    points = rng.normal(size=(n_points, 3)) * [1.0, 0.3, 0.01]  # flat, anisotropic cloud
    queries = np.concatenate([rng.normal(size=(300, 3)), 50.0 * rng.normal(size=(20, 3))])
    distance, index = NearestPoints(points, leaf_size=leaf_size, graph=graph).query(queries)
    expected_distance, expected_index = _brute_force(points, queries)
    np.testing.assert_allclose(distance, expected_distance, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(index, expected_index)
    np.testing.assert_array_equal(distance, cKDTree(points).query(queries)[0])


@GRAPH
def test_ties_give_the_lowest_index(graph):
    rng = np.random.default_rng(3)
    grid = np.stack(np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    points = np.concatenate([grid, grid])  # every point twice
    points = points[rng.permutation(len(points))]
    queries = grid[rng.integers(len(grid), size=200)] + rng.choice([0.0, 0.5], size=(200, 3))
    distance, index = NearestPoints(points, graph=graph).query(queries)
    expected_distance, expected_index = _brute_force(points, queries)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)


@GRAPH
def test_guesses_never_change_the_answer(graph):
    rng = np.random.default_rng(5)
    points = rng.uniform(size=(2000, 3))
    queries = rng.uniform(-0.2, 1.2, size=(500, 3))
    search = NearestPoints(points, graph=graph)
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


@GRAPH
@pytest.mark.parametrize("radius", [0.05, 0.3, 2.0])
def test_query_within_a_radius_matches_brute_force(radius, graph):
    rng = np.random.default_rng(7)
    points = rng.normal(size=(500, 3)) * [1.0, 0.5, 0.05]
    points = np.concatenate([points, points[:50]])  # ties: the lowest index must win
    walk = np.cumsum(rng.normal(scale=0.05, size=(200, 3)), axis=0)  # runs of neighbours
    queries = np.concatenate([walk, rng.normal(size=(200, 3)) * 3.0, points[:20]])
    distance, index = NearestPoints(points, graph=graph).query_within(queries, radius)
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


def _surface_cases(rng):
    """Surface-like point sets (N, 3): a noisy patch with exact duplicates, a cylinder on a
    regular grid and a cube lattice (many points equally near a query), and a flat patch (no
    graph)."""
    xy = rng.uniform(-0.01, 0.01, (400, 2))
    patch = np.c_[xy, 0.0005 * rng.normal(size=400)]
    patch[:100] = patch[100:200]  # exact duplicates
    angle, height = np.meshgrid(np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False),
                                np.linspace(0.0, 0.05, 15))
    cylinder = np.c_[0.02 * np.cos(angle.ravel()), 0.02 * np.sin(angle.ravel()), height.ravel()]
    lattice = 0.003 * np.stack(np.meshgrid(*[np.arange(8.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    flat = np.c_[rng.uniform(-0.01, 0.01, (300, 2)), np.zeros(300)]
    return {"patch": patch, "cylinder": cylinder, "lattice": lattice, "flat": flat}


@pytest.mark.parametrize("case", ["patch", "cylinder", "lattice", "flat"])
def test_searches_from_the_last_answer_give_what_a_full_search_gives(case):
    """Random walks of query points (small steps and jumps, as contact points move in ISF), each
    searched from its previous answer: every answer is the brute-force one."""
    rng = np.random.default_rng(len(case))
    points = _surface_cases(rng)[case]
    search = NearestPoints(points, graph=True)
    assert bool(len(search.tree.graph.indptr)) == (case != "flat")  # a flat set has no graph: the tree
    scratch = search_scratch()
    n_walkers = 20
    last = np.full(n_walkers, -1, np.int64)
    position = points[rng.integers(len(points), size=n_walkers)] + [0.0, 0.0, 0.002]
    for step in range(200):
        jump = rng.random(n_walkers) < 0.05
        position += np.where(jump[:, None], 0.004, 0.0002) * rng.normal(size=position.shape)
        for g, (x, y, z) in enumerate(position):
            index, d2 = nearest_point(x, y, z, last[g], points, search.tree, scratch, np.inf)
            last[g] = index
            d2_all = ((points - position[g]) ** 2).sum(axis=1)
            assert (index, d2) == (int(d2_all.argmin()), float(d2_all.min())), (step, g)


def _flat_cloud_with_copies(seed):
    """300 distinct points of a flattened Gaussian cloud, then exact copies of the first 20:
    ``(points, graph, d2)`` with the graph of :func:`neighbour_graph` and the squared distances
    between the distinct points (inf on the diagonal)."""
    distinct = np.random.default_rng(seed).normal(size=(300, 3)) * [1.0, 0.4, 0.05]
    points = np.concatenate([distinct, distinct[:20]])
    d2 = ((distinct[:, None] - distinct[None]) ** 2).sum(axis=2)
    np.fill_diagonal(d2, np.inf)
    return points, neighbour_graph(points), d2


def test_the_graph_links_each_point_to_its_nearest_and_copies_to_their_first():
    """Two properties of any Delaunay graph, checked by brute force on the distinct points: each
    point's nearest other point is its neighbour, and the graph is symmetric; an exact copy of
    an earlier point lists that point and is no one's neighbour."""
    points, graph, d2 = _flat_cloud_with_copies(4)
    indptr, indices = graph.indptr, graph.indices
    distinct = points[:300]
    assert len(indptr) == len(points) + 1 and np.all(np.diff(indptr) > 0)
    neighbours = [set(indices[indptr[i]:indptr[i + 1]].tolist()) for i in range(len(points))]
    for i in range(len(distinct)):
        assert int(d2[i].argmin()) in neighbours[i]
        assert all(i in neighbours[j] for j in neighbours[i])
        assert not neighbours[i] & set(range(300, 320))
    for copy in range(300, 320):
        assert copy - 300 in neighbours[copy]


def test_the_graph_lists_neighbours_nearest_first_with_the_walks_cutoffs():
    """Each point's neighbours come nearest first, the first is its nearest other point (brute
    force), and each cutoff is a quarter of the squared distance to that neighbour, just below."""
    points, graph, d2 = _flat_cloud_with_copies(6)
    indptr, indices, cutoff = graph.indptr, graph.indices, graph.cutoff
    for i in range(len(points)):
        listed = indices[indptr[i]:indptr[i + 1]]
        squared = ((points[listed] - points[i]) ** 2).sum(axis=1)
        assert np.all(np.diff(squared) >= 0.0)
        quarter = cutoff[indptr[i]:indptr[i + 1]]
        assert np.all(quarter <= squared / 4.0) and np.allclose(quarter, squared / 4.0, rtol=1e-8, atol=0.0)
        if i < 300:  # a distinct point
            assert listed[0] == int(d2[i].argmin())
        else:
            assert listed[0] == i - 300 and quarter[0] == 0.0  # a copy: its first copy, at 0


def test_no_graph_for_too_few_or_flat_points():
    rng = np.random.default_rng(0)
    assert len(neighbour_graph(np.eye(3)).indptr) == 0
    assert len(neighbour_graph(np.concatenate([np.eye(3)] * 4)).indptr) == 0  # 3 distinct points
    flat = np.c_[rng.normal(size=(50, 2)), np.zeros(50)] @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    assert len(neighbour_graph(flat).indptr) == 0  # a tilted plane
    assert len(neighbour_graph(flat + 1e-3 * rng.normal(size=flat.shape)).indptr) == len(flat) + 1


def test_plans_are_the_same_with_and_without_the_graph(monkeypatch):
    """A noisy, partial point cloud planned twice, once with the Delaunay walks and once with the
    k-d tree alone (no graph for any point set): the same grasps, number for number."""
    import isf
    from isf.search import _neighbour_graph as neighbour_graph

    rng = np.random.default_rng(2)
    surface = isf.open_object("shape:cylinder")
    side = surface.points[:, 1] > 0.0  # one side, as a camera sees it
    cloud = surface.points[side] + rng.normal(scale=0.0005, size=(int(side.sum()), 3))
    gripper = isf.load_gripper("three-finger")

    def grasps(graph):
        obj = isf.load_object(cloud)
        result = isf.plan(gripper, obj, samples=8, seed=1)
        assert bool(len(obj.search.tree.graph.indptr)) == graph
        return [(g.collision_free, g.fit.mean_distance, g.fit.T_object_gripper.tobytes(),
                 g.fit.q.tobytes()) for g in result.grasps]

    walked = grasps(graph=True)
    monkeypatch.setattr(neighbour_graph, "MAX_POINTS", 0)
    assert walked == grasps(graph=False)


def test_a_graph_added_later_changes_no_answer_and_leaves_the_old_arrays_valid():
    rng = np.random.default_rng(5)
    points = _surface_cases(rng)["cylinder"]
    search = NearestPoints(points)
    assert not search.has_graph
    before = search.tree
    queries = points[rng.integers(len(points), size=300)] + 0.002 * rng.normal(size=(300, 3))
    guess = rng.integers(len(points), size=300)
    expected = search.query(queries, guess)
    assert search.add_graph() and search.has_graph
    assert search.add_graph()  # built once; later calls only report it
    assert search.tree is not before and search.tree.kd is before.kd
    for answer in (search.query(queries, guess), NearestPoints(points, graph=True).query(queries, guess)):
        np.testing.assert_array_equal(answer[0], expected[0])
        np.testing.assert_array_equal(answer[1], expected[1])
    np.testing.assert_array_equal(expected[1], _brute_force(points, queries)[1])


def test_a_deferred_graph_is_built_once_its_searches_have_paid_for_it(monkeypatch):
    from isf.collision import surface_distance as collision_surface
    from isf.collision.surface_distance import TangentPlanes

    monkeypatch.setattr(collision_surface, "GRAPH_PAYBACK", 3)
    points = _surface_cases(np.random.default_rng(6))["cylinder"]  # 600 points
    normals = points * [1.0, 1.0, 0.0] / 0.02
    planes = TangentPlanes(points, normals, 0.003, graph="deferred")
    planes.note_searches(1799)
    assert not planes.tree.has_graph
    planes.note_searches(1)  # 3 per point
    assert planes.tree.has_graph
    assert not TangentPlanes(points, normals, 0.003).tree.has_graph
    assert TangentPlanes(points, normals, 0.003, graph=True).tree.has_graph
    with pytest.raises(ValueError, match="deferred"):
        TangentPlanes(points, normals, 0.003, graph="later")


def test_plans_are_the_same_whether_the_dense_planes_graph_comes_early_or_never(monkeypatch):
    """A coarse mesh is resampled densely for the repair; its planes' graph built after the first
    searches (mid-plan) or never: the same grasps, number for number."""
    import isf
    from isf.collision import surface_distance as collision_surface
    from isf.collision.surface_distance import mesh_memo

    gripper = isf.load_gripper("three-finger")

    def grasps(payback):
        monkeypatch.setattr(collision_surface, "GRAPH_PAYBACK", payback)
        obj = isf.open_object("shape:cylinder", max_points=600)
        result = isf.plan(gripper, obj, samples=8, seed=3)
        dense = [side.planes for key, side in mesh_memo(obj).items() if key[0] == "repair surface"]
        # a graph only comes from the repair's counted searches: there were some
        assert len(dense) == 1 and dense[0].tree.has_graph == (payback < 10**6)
        return [(g.collision_free, g.fit.mean_distance, g.fit.T_object_gripper.tobytes(),
                 g.fit.q.tobytes()) for g in result.grasps]

    assert grasps(0.05) == grasps(10**9)
