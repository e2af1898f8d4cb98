"""isf.search.point_grid against brute force: every point of a ball (and of a box) is listed, each once."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from isf.search.point_grid import MAX_CELLS, PointGrid, ball_box_candidates


def _candidates(grid: PointGrid, centre, radius) -> np.ndarray:
    """The candidates of a ball alone (an unbounded box)."""
    out, unbounded = np.empty(len(grid.points), dtype=np.int64), np.full(3, np.inf)
    return out[:ball_box_candidates(np.asarray(centre, float), float(radius), np.eye(3), np.zeros(3),
                                    -unbounded, unbounded, grid.arrays, out)]


@pytest.mark.parametrize("seed", range(4))
def test_candidates_hold_every_point_in_the_ball_once(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=0.03, size=(3000, 3))
    points[:50] = points[50:100]  # duplicates
    grid = PointGrid(points, cell=rng.uniform(0.002, 0.01))
    for _ in range(50):
        centre = rng.normal(scale=0.05, size=3)
        radius = rng.uniform(0.0, 0.04)
        found = _candidates(grid, centre, radius)
        assert len(np.unique(found)) == len(found)
        inside = np.flatnonzero(np.linalg.norm(points - centre, axis=1) <= radius)
        assert set(inside) <= set(found)


def test_points_on_cell_faces_and_flat_sets_are_found():
    # a flat grid of points lying exactly on cell boundaries (z = 0: one cell thick)
    xy = np.stack(np.meshgrid(*[np.arange(-10, 11) * 0.004] * 2), axis=-1).reshape(-1, 2)
    points = np.c_[xy, np.zeros(len(xy))]
    grid = PointGrid(points, cell=0.004)
    for centre, radius in (((0.0, 0.0, 0.0), 0.004), ((0.004, -0.008, 0.001), 0.0041),
                           ((0.04, 0.04, 0.0), 0.0), ((0.0, 0.0, 0.05), 0.05)):
        inside = np.flatnonzero(np.linalg.norm(points - np.array(centre), axis=1) <= radius)
        assert set(inside) <= set(_candidates(grid, centre, radius))
    assert len(_candidates(grid, (0.0, 0.0, 0.1), 0.01)) == 0  # a ball far off the set


def test_a_widely_spread_set_keeps_the_grid_small():
    points = np.array([[0.0, 0.0, 0.0], [100.0, 100.0, 100.0], [50.0, 20.0, 70.0]])
    grid = PointGrid(points, cell=0.001)
    assert np.prod(grid.arrays.shape) <= 2 * MAX_CELLS
    assert set(_candidates(grid, points[2], 1e-3)) >= {2}


@pytest.mark.parametrize("seed", range(4))
def test_ball_box_candidates_hold_every_point_in_the_ball_and_the_box_once(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=0.03, size=(3000, 3))
    grid = PointGrid(points, cell=rng.uniform(0.002, 0.01))
    out = np.empty(len(points), dtype=np.int64)
    fewer = 0
    for _ in range(50):
        centre = rng.normal(scale=0.03, size=3)
        radius = rng.uniform(0.0, 0.05)
        R = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
        origin = rng.normal(scale=0.02, size=3)
        half = rng.uniform(0.001, 0.02, 3)  # a flat or thin box in the pose's frame
        box_lo, box_hi = -half + rng.normal(scale=0.005, size=3), half
        found = out[:ball_box_candidates(centre, radius, R, origin, box_lo, box_hi, grid.arrays,
                                         out)].copy()
        assert len(np.unique(found)) == len(found)
        local = (points - origin) @ R
        inside = np.flatnonzero((np.linalg.norm(points - centre, axis=1) <= radius)
                                & (local >= box_lo).all(axis=1) & (local <= box_hi).all(axis=1))
        assert set(inside) <= set(found)
        fewer += len(found) < len(_candidates(grid, centre, radius))
    assert fewer > 10  # the box leaves cells out
