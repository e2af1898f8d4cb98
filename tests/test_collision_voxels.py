"""The collision checks' voxels, element tests and memos against independent references."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh
from test_collision import jaw_gripper, mesh_object, pose

from isf.collision._elements import Element
from isf.collision.checker import CollisionChecker
from isf.collision.voxels import SurfaceVoxels, _gaps
from isf.gripper.model import LinkGeometry


def _torus() -> trimesh.Trimesh:
    """A closed mesh with a hole through it (its hole is outside, its tube inside)."""
    return trimesh.creation.torus(major_radius=0.02, minor_radius=0.006, major_sections=48,
                                  minor_sections=16)


def _mesh_distances(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Exact distance of each point to the mesh's triangles (coal)."""
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(mesh.faces), len(mesh.vertices))
    model.addVertices(np.ascontiguousarray(mesh.vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(mesh.faces, dtype=np.int64))
    model.endModel()
    point, request = coal.Sphere(0.0), coal.DistanceRequest()
    return np.array([coal.distance(point, coal.Transform3s(np.eye(3), p), model, coal.Transform3s(),
                                   request, coal.DistanceResult()) for p in points])


@pytest.mark.parametrize("make", [_torus, lambda: trimesh.creation.icosphere(2, radius=0.015)])
def test_clear_boxes_lie_outside_the_mesh(make):
    mesh = make()
    voxels = SurfaceVoxels(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    centre = rng.uniform(lo - 0.005, hi + 0.005, (3000, 3))
    half = rng.uniform(0.0, 0.003, (3000, 1))
    clear = voxels.clear(centre - half, centre + half)
    assert 0.2 < clear.mean() < 0.95  # both answers occur
    # every corner and the centre of a clear box is outside the mesh, and the box misses it
    signs = np.array(list(np.ndindex(2, 2, 2))) * 2 - 1
    corners = centre[:, None, :] + half[:, None, :] * signs
    probe = np.concatenate([centre[clear], corners[clear].reshape(-1, 3)])
    assert not mesh.contains(probe).any()
    assert (_mesh_distances(mesh, centre[clear]) >= half[clear, 0] - 1e-12).all()
    # a box around a point inside the mesh, or touching its surface, is never clear
    inside = trimesh.sample.volume_mesh(mesh, 200)
    assert not voxels.clear(inside, inside).any()
    surface = mesh.sample(200)
    assert not voxels.clear(surface - 1e-4, surface + 1e-4).any()


def test_distance_below_never_exceeds_the_mesh_distance():
    mesh = _torus()
    voxels = SurfaceVoxels(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(4)
    lo, hi = mesh.bounds
    points = np.concatenate([rng.uniform(lo - 0.03, hi + 0.03, (400, 3)),
                             trimesh.sample.volume_mesh(mesh, 100)])
    below = voxels.distance_below(points)
    exact = _mesh_distances(mesh, points)
    assert (below <= exact + 1e-12).all()
    # and not vacuous: at least the Euclidean distance over sqrt(3) (a Chebyshev bound), less a
    # voxel on each side and the triangles' overreach (small on this fine mesh)
    assert (below >= exact / np.sqrt(3) - 3 * voxels.size).all()


@pytest.mark.parametrize("fill", [0.0, 0.01, 0.05, 0.3])
def test_voxel_gaps_are_the_box_to_box_distances_to_the_blocked_voxels(fill):
    rng = np.random.default_rng(int(fill * 100))
    for _ in range(8):
        shape = tuple(int(n) for n in rng.integers(1, 13, 3))
        blocked = rng.random(shape) < fill
        cells = np.argwhere(np.ones(shape, bool))
        sites = np.argwhere(blocked)
        if len(sites):  # brute force: every voxel against every blocked one
            apart = np.maximum(np.abs(cells[:, None, :] - sites[None, :, :]) - 1, 0)
            expected = (apart ** 2).sum(axis=-1).min(axis=1).reshape(shape)
        else:  # none blocked: the grid's squared diagonal
            expected = np.full(shape, sum(n * n for n in shape))
        assert np.array_equal(_gaps(blocked), expected.astype(float))


def test_object_depth_matches_the_distance_to_a_convex_element_surface():
    box = trimesh.creation.box(extents=(0.02, 0.01, 0.03))
    element = Element(LinkGeometry("link", "box", np.asarray(box.vertices), np.asarray(box.faces)), 0,
                      np.random.default_rng(0))
    T = trimesh.transformations.rotation_matrix(0.7, (1.0, 2.0, 0.5))
    T[:3, 3] = [0.01, -0.02, 0.005]
    rng = np.random.default_rng(5)
    for _ in range(5):
        points = T[:3, 3] + rng.normal(scale=0.01, size=(300, 3))
        local = (points - T[:3, 3]) @ T[:3, :3]
        inside = box.contains(local)
        exact = trimesh.proximity.signed_distance(box, local[inside]).max() if inside.any() else 0.0
        assert element.object_depth(points, T, 0.002) == pytest.approx(max(exact, 0.0), abs=1e-9)


def test_checkers_built_again_reuse_their_parts_and_agree():
    gripper = jaw_gripper()
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.02)
    obj = mesh_object(sphere, 2000)
    first, second = CollisionChecker(gripper, obj), CollisionChecker(gripper, obj)
    assert second._elements is first._elements and second._surface is first._surface
    other = CollisionChecker(jaw_gripper(), obj)  # another gripper object: built anew
    assert other._elements is not first._elements
    assert np.array_equal(other._surface.points, first._surface.points)
    for height, q in ((0.016, 0.0205), (0.03, 0.0195), (0.03, 0.0205), (0.05, 0.03)):
        a, b, c = (k.check(pose(height), [q]) for k in (first, second, other))
        assert a == b == c
