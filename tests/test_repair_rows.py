"""The collision repair's row selection against brute force.

The repair (isf.repair.clearance) computes a clearance row in full only when it may be used by a step
or be the deepest row: these tests compare its kernels (isf.repair.rows, the pruned
convex-element rows) and its rows at whole states with straightforward numpy versions that
compute every row.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import isf
from isf.collision.convex_elements import ConvexElements, _reach_box
from isf.collision.surface_distance import NEIGHBOURS
from isf.repair._step import to_object
from isf.repair.clearance import ClearanceRepair
from isf.repair.rows import deepest_rows, undecided
from isf.search.point_grid import PointGrid

ACTIVATION, MAX_ROWS = 0.008, 12


def reference_deepest(violation, element, activation=ACTIVATION, max_rows=MAX_ROWS):
    """Rows within ``activation`` of their floor, the ``max_rows`` most violated per element,
    by element, then violation (descending), then index (a stable sort)."""
    near = np.flatnonzero(violation > -activation)
    order = near[np.lexsort((-violation[near], element[near]))]
    kept, seen = [], {}
    for i in order:
        seen[element[i]] = seen.get(element[i], 0) + 1
        if seen[element[i]] <= max_rows:
            kept.append(i)
    return np.array(kept, dtype=np.int64)


def random_rows(rng, n, n_elements):
    """Violations rounded to 0.1 mm (many ties) and their elements."""
    violation = np.round(rng.normal(-0.004, 0.006, n), 4)
    return violation, rng.integers(0, n_elements, n)


@pytest.mark.parametrize("seed", range(6))
def test_deepest_rows_match_a_stable_sort(seed):
    rng = np.random.default_rng(seed)
    violation, element = random_rows(rng, int(rng.integers(0, 600)), 7)
    np.testing.assert_array_equal(deepest_rows(violation, element, 7, ACTIVATION, MAX_ROWS),
                                  reference_deepest(violation, element))


@pytest.mark.parametrize("seed", range(20))
def test_rows_left_undecided_change_neither_the_rows_used_nor_the_deepest(seed):
    """Unknown rows (true violation at most their bound) are dropped when ``undecided`` says so;
    the rows a step uses (same rows, same order) and the largest violation must not change."""
    rng = np.random.default_rng(seed)
    n_elements = 5
    known_v, known_e = random_rows(rng, int(rng.integers(0, 80)), n_elements)
    true_v, unknown_e = random_rows(rng, int(rng.integers(1, 300)), n_elements)
    slack = rng.exponential(0.002, len(true_v))
    bound = true_v + np.where(rng.random(len(true_v)) < 0.3, 0.0, slack)
    todo = undecided(bound, unknown_e, known_v, known_e, n_elements, ACTIVATION, MAX_ROWS, 0.0)
    # the repair puts the sample rows first, then the known ones
    all_v, all_e = np.r_[true_v, known_v], np.r_[unknown_e, known_e]
    kept = np.r_[np.flatnonzero(todo), len(true_v) + np.arange(len(known_v))]
    full = reference_deepest(all_v, all_e)
    np.testing.assert_array_equal(kept[reference_deepest(all_v[kept], all_e[kept])], full)
    assert all_v[kept].max() == all_v.max()


# ------------------------------------------------------------------ convex-element rows
def convex_meshes():
    box = trimesh.creation.box(extents=(0.02, 0.012, 0.008))
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.01)  # 1280 faces: planes dropped
    tetra = trimesh.Trimesh([[0, 0, 0], [0.015, 0, 0], [0, 0.015, 0], [0, 0, 0.015]],
                            [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return [(m.vertices, m.faces) for m in (box, sphere, tetra)]


def reference_convex_rows(elements, R_links, origins, points, reach):
    """Every row of every convex element, brute force: (element, point, violation, foot)."""
    rows = []
    for c in range(len(elements)):
        planes = elements._planes[elements._plane_start[c]:elements._plane_start[c + 1]]
        local = (points - origins[c]) @ R_links[c]
        sd = local @ planes[:, :3].T - planes[:, 3]
        best = sd.max(axis=1)
        face = sd.argmax(axis=1)
        for k in np.flatnonzero(best < elements.floor[c] + reach):
            foot = local[k] - best[k] * planes[face[k], :3]
            rows.append((c, k, elements.floor[c] - best[k], foot))
    return rows


@pytest.mark.parametrize("seed", range(4))
def test_convex_rows_keep_the_deepest_of_every_element(seed):
    rng = np.random.default_rng(seed)
    meshes = convex_meshes()
    floor = np.array([-0.001, 0.0005, 0.0])
    elements = ConvexElements(meshes, np.arange(3), floor)
    points = rng.uniform(-0.02, 0.02, (4000, 3))
    grid = PointGrid(points, 0.004)
    R = np.stack([trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
                  for _ in range(3)])
    p = rng.uniform(-0.005, 0.005, (3, 3))
    reach, keep = 0.003, 5
    out = elements.rows(np.eye(4), R, p, grid, reach, keep)
    expected = reference_convex_rows(elements, R, p, points, reach)
    by_key = {(c, k): (v, foot) for c, k, v, foot in expected}
    # every row is a true row, with its depth and foot
    for c, k, depth, foot in zip(out.element, out.point, out.depth, out.foot):
        v, ref_foot = by_key[(c, k)]
        assert elements.floor[c] - depth == pytest.approx(v, abs=1e-12)
        np.testing.assert_allclose(foot, ref_foot, atol=1e-12)
    # element by element, points in index order
    order = np.lexsort((out.point, out.element))
    np.testing.assert_array_equal(order, np.arange(len(order)))
    # of every element, exactly the `keep` most violated rows of its ball and those tied with
    # the last of them
    for c in range(3):
        centre = R[c] @ elements._centre[c] + p[c]
        in_ball = {k for cc, k, _, _ in expected if cc == c
                   and np.linalg.norm(points[k] - centre) <= elements._radius[c] + reach}
        violations = sorted((v for cc, k, v, _ in expected if cc == c and k in in_ball), reverse=True)
        cut = violations[keep - 1] if len(violations) >= keep else -np.inf
        wanted = {k for cc, k, v, _ in expected if cc == c and k in in_ball and v >= cut}
        assert set(out.point[out.element == c]) == wanted
        assert len(wanted) >= min(keep, len(in_ball))
    assert sum(len(out.point[out.element == c]) for c in range(3)) >= 1


@pytest.mark.parametrize("margin", [0.0, 0.003])
def test_reach_box_holds_every_point_less_than_the_margin_above_all_faces(margin):
    rng = np.random.default_rng(7)
    elements = ConvexElements(convex_meshes(), np.arange(3), np.zeros(3))
    for c in range(3):
        planes = elements._planes[elements._plane_start[c]:elements._plane_start[c + 1]]
        box = _reach_box(planes, elements._centre[c], margin)
        spread = elements._radius[c] + margin + 0.005
        points = elements._centre[c] + rng.uniform(-spread, spread, (20000, 3))
        near = (points @ planes[:, :3].T - planes[:, 3]).max(axis=1) < margin
        assert near.sum() > 100
        assert ((points[near] >= box[0]) & (points[near] <= box[1])).all()
    # the box mesh: its own extents grown by the margin (each side's two triangles, one plane)
    planes = elements._planes[:elements._plane_start[1]]
    box = _reach_box(planes, elements._centre[0], margin)
    np.testing.assert_allclose(box[1], np.array([0.01, 0.006, 0.004]) + margin, atol=1e-9)
    np.testing.assert_allclose(box[0], -box[1], atol=1e-9)


# ------------------------------------------------------------- rows at whole repair states
@pytest.fixture(scope="module")
def hand_on_cylinder(hand, hand_cylinder):
    """The three-finger hand and a closed mesh cylinder the repair resamples densely."""
    return hand, hand_cylinder


def reference_violations(repairer: ClearanceRepair, T, R, p):
    """Every clearance row candidate of a state, as the repair defines them (no pruning):
    samples of elements near the object that lie near the object or inside it (by trimesh's
    point-in-mesh test) get the best of the tangent planes of their 6 nearest dense points;
    every object point inside or near a convex element gets its row."""
    obj, cfg = repairer.object, repairer.config
    sel = repairer._near_samples(T, R, p)
    owner, local = repairer._owner[sel], repairer._points_link[sel]
    world = to_object(T, R, p, owner, local)  # the samples where the repair places them
    dist, _ = obj.nearest(world)
    inside = trimesh.Trimesh(obj.mesh_vertices, obj.mesh_faces).contains(world)
    close = np.flatnonzero(inside | (dist < cfg.activation + cfg.margin + 2 * obj.spacing))
    planes = repairer._planes
    _, idx = planes.tree.query_k(world[close], NEIGHBOURS)
    h = np.einsum("mki,mki->mk", world[close, None, :] - planes.points[idx], planes.normals[idx])
    heights = h.max(axis=1)
    normals = planes.normals[idx[np.arange(len(close)), h.argmax(axis=1)]]
    convex = repairer._convex
    rows = convex.rows(T, R, p, repairer._grid, 0.003 + cfg.margin, len(planes.points))
    return (np.r_[repairer._floor[sel][close] - heights, convex.floor[rows.element] - rows.depth],
            np.r_[repairer._element[sel][close], convex.element[rows.element]],
            np.r_[normals, rows.normal])


@pytest.mark.parametrize("config", [isf.RepairConfig(),  # the default: two rows per element
                                    isf.RepairConfig(max_rows=12, activation=0.008)])
def test_repair_rows_at_random_states_are_those_of_a_full_evaluation(hand_on_cylinder, config):
    gripper, obj = hand_on_cylinder
    repairer = ClearanceRepair(gripper, obj, config)
    assert repairer._resampled  # the dense planes differ from the object's own points
    rng = np.random.default_rng(3)
    n_used = 0
    for _ in range(12):
        T = np.eye(4)
        T[:3, :3] = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
        # the palm origin within a few cm of the object's centre: links cross its surface
        T[:3, 3] = obj.points.mean(axis=0) + rng.normal(scale=0.03, size=3)
        q = rng.uniform(gripper.lower, gripper.upper)
        R, p, _ = repairer._frame_jacobians(q, repairer._frames)
        rows = repairer._violations(T, R, p)
        violation, element, normal = reference_violations(repairer, T, R, p)
        used = repairer._active_rows(rows.violation, rows.element)
        expected = reference_deepest(violation, element, config.activation, config.max_rows)
        # the same rows; their values to round-off (the checks' compiled tangent-plane heights
        # sum in another order than this reference's einsum)
        np.testing.assert_allclose(rows.violation[used], violation[expected], rtol=1e-12, atol=1e-17)
        np.testing.assert_array_equal(rows.element[used], element[expected])
        np.testing.assert_allclose(rows.normal[used], normal[expected], rtol=0, atol=1e-15)
        if len(violation):  # the deepest row is always computed
            assert rows.violation.max() == pytest.approx(violation.max(), rel=1e-12, abs=1e-17)
        else:  # nothing within reach
            assert len(rows.violation) == 0
        n_used += len(used)
    assert n_used > 4 * config.max_rows  # the states did touch the object


@pytest.mark.parametrize("keep_mesh", [True, False])
def test_only_samples_near_or_inside_the_object_get_rows(hand_on_cylinder, keep_mesh):
    """Samples far outside the object get no row; samples deep inside do, however far from the
    surface (inside told by the mesh's voxels, or for a point cloud by the nearest point's
    plane)."""
    from isf.repair.clearance import _NO_ROWS

    gripper, cylinder = hand_on_cylinder
    obj = cylinder if keep_mesh else isf.ObjectSurface(cylinder.points, cylinder.normals,
                                                       spacing=cylinder.spacing)
    repairer = ClearanceRepair(gripper, obj)
    assert (repairer._voxels is not None) == keep_mesh
    cfg = repairer.config
    reach = cfg.activation + cfg.margin + 2 * obj.spacing
    centre = 0.5 * (obj.points.min(axis=0) + obj.points.max(axis=0))  # the axis is along x
    radius = np.linalg.norm(obj.points[:, 1:] - centre[1:], axis=1).max()
    rng = np.random.default_rng(0)
    axis = centre + np.c_[rng.uniform(-0.03, 0.03, 20), np.zeros((20, 2))]  # deep inside
    directions = rng.normal(size=(20, 2))
    far = centre + np.c_[rng.uniform(-0.03, 0.03, 20), (radius + 3 * reach) * directions
                         / np.linalg.norm(directions, axis=1)[:, None]]  # far out, sideways
    world = np.concatenate([axis, far])
    dist, _ = obj.nearest(world)
    assert dist.min() > reach  # all of them beyond reach of every object point
    floor = np.full(len(world), cfg.margin)
    element = np.zeros(len(world), dtype=np.int64)
    no_guess = np.full(len(world), -1, dtype=np.int64)
    kept, normals, violation, nearest = repairer._sample_rows(world, no_guess, floor, element,
                                                              _NO_ROWS)
    assert set(kept.tolist()) <= set(range(20))  # no far-outside sample
    assert len(kept) >= 1 and np.all(violation > reach)  # the deepest inside ones, violated
    np.testing.assert_array_equal(nearest[:20], obj.nearest(world[:20])[1])  # inside: searched
    searched = nearest[20:] >= 0  # beyond reach: only where the voxels cannot tell outside
    assert not searched.any() if keep_mesh else searched.all()
    np.testing.assert_array_equal(nearest[20:][searched], obj.nearest(world[20:][searched])[1])
    guess = rng.integers(len(obj.points), size=len(world))  # guesses change no answer
    again = repairer._sample_rows(world, guess, floor, element, _NO_ROWS)
    for a, b in zip(again, (kept, normals, violation, nearest)):
        np.testing.assert_array_equal(a, b)
