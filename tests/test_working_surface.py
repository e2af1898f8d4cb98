"""The working surface: a dense object thinned to the spacing the gripper can resolve."""

import numpy as np
import pytest
from _builders import cylinder_object
from scipy.spatial import cKDTree

import isf
from isf.exceptions import InvalidInputError
from isf.object.surface import ObjectSurface
from isf.planning._working_surface import (
    SPACING_FACTOR,
    contact_spacing,
    working_spacing,
    working_surface,
)


def dense_sphere(n=40_000, radius=0.02, seed=0) -> ObjectSurface:
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    area = 4 * np.pi * radius**2
    return ObjectSurface(radius * normals, normals, spacing=np.sqrt(area / n), name="sphere")


def test_thins_to_one_point_per_voxel_of_the_spacing():
    obj, h = dense_sphere(), 0.002
    thin = working_surface(obj, h)
    # Every kept row is a row of the object, with its own normal.
    rows = cKDTree(obj.points).query(thin.points)[1]
    np.testing.assert_array_equal(obj.points[rows], thin.points)
    np.testing.assert_array_equal(obj.normals[rows], thin.normals)
    # One point per occupied voxel of edge h (counted here without the library's grid code) ...
    occupied = {tuple(v) for v in np.floor(obj.points / h).astype(np.int64)}
    assert thin.n_points == len(occupied)
    assert len({tuple(v) for v in np.floor(thin.points / h).astype(np.int64)}) == thin.n_points
    # ... so every object point lies within a voxel diagonal of a kept one.
    assert cKDTree(thin.points).query(obj.points)[0].max() <= np.sqrt(3) * h
    assert thin.spacing == h and thin.name == obj.name


def test_an_object_at_least_as_coarse_is_kept_as_it_is():
    obj = dense_sphere(n=2000)
    assert working_surface(obj, obj.spacing) is obj
    assert working_surface(obj, 0.0) is obj


def test_contact_spacing_is_the_median_neighbour_gap_on_each_surface(paper_gripper):
    gaps = []
    for k in range(len(paper_gripper.surfaces)):
        points = paper_gripper.points_link[paper_gripper.point_surface == k]
        d = np.linalg.norm(points[:, None] - points[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        gaps.append(d.min(axis=1))
    expected = np.median(np.concatenate(gaps))
    assert contact_spacing(paper_gripper) == pytest.approx(expected, rel=1e-12)
    assert working_spacing(paper_gripper) == pytest.approx(SPACING_FACTOR * expected)


def test_plan_on_a_dense_object_is_as_good_as_on_every_point(paper_gripper):
    dense = cylinder_object(0.012, n=30_000)
    runs = {}
    for spacing in ("auto", None):
        result = isf.plan(paper_gripper, dense, samples=12, seed=0, working_spacing=spacing)
        free = result.collision_free_grasps()
        assert free
        # fit error against every point of the dense object, whatever the plan matched against
        errors = []
        for g in free:
            _, i = dense.nearest(g.fit.contact_points)
            d = np.einsum("ij,ij->i", g.fit.contact_points - dense.points[i], dense.normals[i])
            errors.append(np.abs(d).mean())
        runs[spacing] = (result.stats.surface_points, len(free), float(np.mean(errors)))
    (thin_points, thin_free, thin_error), (all_points, all_free, all_error) = runs["auto"], runs[None]
    assert all_points == dense.n_points
    assert thin_points < dense.n_points / 4
    assert thin_free >= all_free - 2
    assert thin_error <= all_error + 5e-5  # m (at a 4 mm spacing it is 0.09 mm worse)


@pytest.mark.parametrize("value", [0.0, -1e-3, float("nan"), "fine", True])
def test_bad_working_spacing_is_refused(paper_gripper, value):
    with pytest.raises(InvalidInputError, match="working_spacing"):
        isf.plan(paper_gripper, cylinder_object(0.012, n=2000), samples=1, working_spacing=value)
