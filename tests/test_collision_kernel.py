"""The compiled collision check against independent references: every sample evaluated by
brute force, coal's exact distances, and the tangent-plane estimate of every point."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh
from test_collision import CUBE, GAP, _coal_bvh, jaw_gripper, mesh_object, pose

from isf.collision._elements import Element, point_triangle_distance
from isf.collision.checker import CollisionChecker
from isf.collision.kernel import reverse_clearance
from isf.gripper.model import LinkGeometry


def _coal_distance(model, point, pose=None) -> float:
    at = coal.Transform3s() if pose is None else coal.Transform3s(pose[:3, :3], pose[:3, 3])
    return coal.distance(coal.Sphere(0.0), coal.Transform3s(np.eye(3), point), model, at,
                         coal.DistanceRequest(), coal.DistanceResult())


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(2, radius=0.02),
                                  trimesh.creation.box(extents=(0.03, 0.01, 0.02)),
                                  trimesh.creation.torus(0.02, 0.005, major_sections=16, minor_sections=8)])
def test_point_triangle_distances_match_coal(mesh):
    rng = np.random.default_rng(5)
    points = rng.normal(scale=0.02, size=(200, 3))
    model = _coal_bvh(mesh.vertices, mesh.faces)
    exact = np.array([_coal_distance(model, p) for p in points])
    assert np.allclose(point_triangle_distance(points, mesh.triangles), exact, atol=1e-12)


def test_degenerate_triangles_measure_to_their_edges():
    line = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],  # collinear
                     [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]])  # a point
    points = np.array([[1.0, 1.0, 0.0], [3.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 2.0]])
    assert np.allclose(point_triangle_distance(points, line), [1.0, 1.0, 1.0, 2.0])


def _brute_depths(checker: CollisionChecker, T: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Each element's depth into the object from every one of its samples (the estimate at
    each) and every object point inside it."""
    links = checker.gripper.frame_kinematics_many(np.asarray(q, float)[None], checker._frame_ids)
    out = []
    for e in checker._elements:
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = links.rotations[0, e.frame], links.positions[0, e.frame]
        M = T @ M
        sd = checker._surface.evaluate(e.samples @ M[:3, :3].T + M[:3, 3])[0]
        out.append(max(0.0, -sd.min(), e.object_depth(checker._points, M, checker.tolerance)))
    return np.array(out)


@pytest.mark.parametrize("keep_mesh", [True, False])
def test_verdicts_equal_evaluating_every_sample(keep_mesh):
    # Grasp-like poses of the jaw around a 2 cm sphere, and some pressed into a cube: every
    # element's verdict equals that of the estimate at all of its samples (none lies wholly
    # inside), and the depth read is that of an evaluated sample, within the prediction bound
    # of the deepest of all.
    gripper = jaw_gripper()
    rng = np.random.default_rng(3)
    checked = colliding = 0
    for shape in (trimesh.creation.icosphere(4, radius=0.02), trimesh.creation.box(extents=(2 * CUBE,) * 3)):
        checker = CollisionChecker(gripper, mesh_object(shape, 4000, keep_mesh=keep_mesh))
        for _ in range(10):
            T = pose(rng.uniform(0.018, 0.026), rng.uniform(-0.004, 0.004, 2))
            T = T @ trimesh.transformations.rotation_matrix(rng.uniform(-0.2, 0.2), rng.normal(size=3))
            q = [rng.uniform(0.0185, 0.0225)]
            brute = _brute_depths(checker, T, q)
            report = checker.check(T, q)
            expected = tuple(dict.fromkeys(e.link for e, d in zip(checker._elements, brute)
                                           if d > checker.tolerance))
            assert report.colliding_links == expected, (brute, report)
            assert brute.max() - 5e-4 <= report.penetration <= brute.max() + 1e-12
            checked += 1
            colliding += not report.collision_free
    assert 5 <= colliding <= checked - 5  # both verdicts are exercised


def test_clearance_probes_match_coal_distances():
    # The reverse step alone: the best candidate of each of the two lowest-indexed elements,
    # its 4 nearest object samples, their exact distances to that element (coal as reference).
    gripper = jaw_gripper()
    checker = CollisionChecker(gripper, mesh_object(trimesh.creation.box(extents=(2 * CUBE,) * 3)))
    rng = np.random.default_rng(9)
    links = gripper.frame_kinematics_many(np.array([[CUBE + GAP]]), checker._frame_ids)
    poses = []
    for e in checker._elements:
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = links.rotations[0, e.frame], links.positions[0, e.frame]
        poses.append(pose(0.03) @ M)
    poses = np.array(poses)
    models = [_coal_bvh(e.mesh.vertices, e.mesh.faces) for e in checker._elements]
    surface = checker._surface
    for _ in range(5):
        owner = rng.choice([0, 1, 3, 4], size=12)
        candidates = rng.uniform(-0.03, 0.03, size=(12, 3))
        measured = rng.uniform(0.001, 0.01, size=12)
        order = np.argsort(measured, kind="stable")
        best = measured.min()
        for e in sorted(set(owner.tolist()))[:2]:
            j = next(j for j in order if owner[j] == e)
            _, probes = surface.tree.query_k(candidates[j], 4)
            for p in surface.points[probes[0]]:
                best = min(best, _coal_distance(models[e], p, poses[e]))
        got = reverse_clearance(measured, candidates, owner, poses, checker._triangles,
                                checker._triangle_start, surface.points, surface.tree.tree, 4)
        assert got == pytest.approx(best, abs=1e-12)


def test_non_convex_depth_equals_the_estimate_at_every_point():
    # A torus element (closed, not convex): the depth of the deepest object point inside it is
    # the estimate's over all points in its box and hull, few or many (the grid only screens).
    ring = trimesh.creation.torus(0.02, 0.006, major_sections=32, minor_sections=12)
    element = Element(LinkGeometry("link", "ring", ring.vertices, ring.faces), 0, np.random.default_rng(0))
    assert element.closed and element.planes is None
    rng = np.random.default_rng(4)
    T = np.eye(4)
    T[:3, :3] = trimesh.transformations.rotation_matrix(0.7, (1.0, 2.0, 0.5))[:3, :3]
    T[:3, 3] = (0.01, -0.02, 0.005)
    for n in (20, 3000):
        local = rng.uniform(element.bounds[0], element.bounds[1], size=(n, 3))
        points = local @ T[:3, :3].T + T[:3, 3]
        inside_hull = (local @ element.hull_planes[:, :3].T - element.hull_planes[:, 3]).max(axis=1) < 0
        brute = max(0.0, -element.surface.evaluate(local[inside_hull])[0].min())
        assert element.object_depth(points, T, 0.002) == pytest.approx(brute, abs=1e-12)
        assert brute > 0.003  # deep points exist


def test_estimates_are_counted():
    checker = CollisionChecker(jaw_gripper(), mesh_object(trimesh.creation.box(extents=(2 * CUBE,) * 3)))
    checker.check(pose(0.3), [CUBE + GAP])  # far above: bounding spheres and a few centres
    far = checker.estimates
    checker.check(pose(0.03), [CUBE - 0.001])  # pads pressed into the sides: many samples
    assert 3 <= far < 30 < checker.estimates - far
