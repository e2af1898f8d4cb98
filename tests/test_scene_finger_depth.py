"""The fingers' local depth bound on a scene (isf.scene.finger_depth) and the local scatter it
reads (Scene.scatter), checked against analytic planes and a box whose edges are known."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from _depth_camera import box_on_table, look_at, render_depth, table_mesh
from _open3d import import_open3d

import isf
from isf.collision.checker import CollisionChecker
from isf.fitting.engine import score_fit
from isf.scene import NOISE_MARGIN, FingerDepth, Settler, load_scene

DOWN = np.diag([-1.0, 1.0, -1.0])  # the gripper's approach (+z) pointing down the scene's z
BOX = (0.05, 0.04, 0.10)  # x, y, z extents, m: flat-parallel closes on the faces y = +-0.02


def _plane(half: float = 0.1, step: float = 0.001):
    """Points of the plane z = 0 on a grid, normals +z."""
    axis = np.arange(-half, half + step / 2, step)
    x, y = np.meshgrid(axis, axis)
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    return points, np.tile([0.0, 0.0, 1.0], (len(points), 1))


def _fingertips_at(gripper, q, height: float) -> np.ndarray:
    """The pose pointing down whose lowest finger vertex is at z = ``height``."""
    T = np.eye(4)
    T[:3, :3] = DOWN
    poses = gripper.link_poses(q)
    lowest = min(float((np.asarray(g.vertices) @ (T @ poses[g.link])[:3, :3].T)[:, 2].min())
                 for g in gripper.geometries if g.link in gripper.contact_links)
    T[2, 3] = height - lowest
    return T


@pytest.mark.parametrize("height", [-0.003, -0.001, 0.0, 0.002])
def test_bound_on_a_plane_is_the_deepest_finger_point_plus_the_scatter_margin(height):
    gripper = isf.load_gripper("flat-parallel")
    points, normals = _plane()
    scatter = 0.0007
    depth = FingerDepth(gripper, points, normals, np.full(len(points), scatter), NOISE_MARGIN)
    q = gripper.q_open
    bound = depth.bound(_fingertips_at(gripper, q, height), q)
    assert bound == pytest.approx(-height + NOISE_MARGIN * scatter, abs=1e-9)


def test_fingers_far_from_the_surface_have_no_bound():
    gripper = isf.load_gripper("flat-parallel")
    points, normals = _plane()
    depth = FingerDepth(gripper, points, normals, np.full(len(points), 0.001), NOISE_MARGIN)
    q = gripper.q_open
    assert depth.bound(_fingertips_at(gripper, q, 0.006), q) == -np.inf  # beyond NEAR (4 mm)


def test_bound_reads_the_scatter_under_the_fingers_only():
    gripper = isf.load_gripper("flat-parallel")
    points, normals = _plane()
    q = gripper.q_open
    T = _fingertips_at(gripper, q, -0.001)
    poses = gripper.link_poses(q)
    finger_xy = np.concatenate([(np.asarray(g.vertices) @ (T @ poses[g.link])[:3, :3].T
                                 + (T @ poses[g.link])[:3, 3])[:, :2]
                                for g in gripper.geometries if g.link in gripper.contact_links])
    low, high = finger_xy.min(axis=0) - 0.006, finger_xy.max(axis=0) + 0.006
    under = np.all((points[:, :2] >= low) & (points[:, :2] <= high), axis=1)
    assert 0 < under.sum() < len(points)
    rough_elsewhere = np.where(under, 0.0005, 0.003)
    rough_under = np.where(under, 0.002, 0.0005)
    bound_elsewhere = FingerDepth(gripper, points, normals, rough_elsewhere, NOISE_MARGIN).bound(T, q)
    bound_under = FingerDepth(gripper, points, normals, rough_under, NOISE_MARGIN).bound(T, q)
    assert bound_elsewhere == pytest.approx(0.001 + NOISE_MARGIN * 0.0005, abs=1e-9)
    assert bound_under == pytest.approx(0.001 + NOISE_MARGIN * 0.002, abs=1e-9)


@pytest.fixture(scope="module")
def box_scene():
    """A 5 x 4 x 10 cm box on the table seen from two sides with 1 mm noise, and the box."""
    box = box_on_table(BOX)
    views = []
    for k, side in enumerate((1.0, -1.0)):
        T = look_at((0.05, side * 0.45, 0.45), (0.0, 0.0, 0.05))
        depth, intrinsics = render_depth([table_mesh(), box], T, noise=0.001, seed=k)
        views.append(isf.SceneView(depth, intrinsics=intrinsics, T_scene_camera=T))
    return load_scene(views, table="auto"), box


def test_scatter_is_the_noise_on_faces_and_more_at_edges(box_scene):
    scene, _ = box_scene
    sx, sy, sz = BOX
    assert scene.scatter.shape == (scene.surface.n_points,)
    assert scene.noise == pytest.approx(float(np.median(scene.scatter)))
    p = scene.surface.points
    # distance of each point to the nearest edge of the box's top face and vertical edges
    dx, dy, dz = sx / 2 - np.abs(p[:, 0]), sy / 2 - np.abs(p[:, 1]), sz - p[:, 2]
    to_edge = np.sort(np.abs(np.column_stack([dx, dy, dz])), axis=1)[:, 1]
    edges, faces = scene.scatter[to_edge < 0.002], scene.scatter[to_edge > 0.01]
    assert len(edges) > 20 and len(faces) > 100
    assert np.median(edges) > 1.15 * np.median(faces)  # 1.24 x with this seed


def _pad_depth(box, gripper, T, q) -> float:
    """Deepest contact point inside the true box, metres (> 0 inside; Open3D signed distance)."""
    o3d = import_open3d()
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(np.asarray(box.vertices, np.float32)),
                     o3d.core.Tensor(np.asarray(box.faces, np.uint32)))
    points, _ = gripper.contact_points(q)
    posed = (points @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
    return float(-rc.compute_signed_distance(o3d.core.Tensor(posed)).numpy().min())


def test_settling_eases_the_fingers_out_to_the_bound_or_says_it_could_not(box_scene):
    # The same grasp on the same observations; only the local scatter differs. None: the
    # bound is the fingers' depth, within 2 mm once settled. 2 mm everywhere: the bound asks
    # the fingers to stay 1 mm out of the observed faces, which they can while touching
    # them (2 mm contact distance). 5 mm: 5.5 mm out, which loses the contact, so the grasp
    # keeps its settled state, marked beyond the bound.
    scene, box = box_scene
    gripper = isf.load_gripper("flat-parallel")
    T = np.eye(4)
    T[:3, :3] = DOWN
    T[:3, 3] = (0.0, 0.0, BOX[2] + 0.05)
    q = np.array([BOX[1] / 2 - 0.001])  # pads 1 mm into the faces y = +-0.02
    assert _pad_depth(box, gripper, T, q) == pytest.approx(0.001, abs=1e-5)
    config = isf.FitConfig()
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    report = checker.check(T, q)
    assert report.collision_free
    fit = score_fit(gripper, scene.surface, T, q, config, isf.FitStatus.CONVERGED, (), 0.0)
    outcomes = {}
    for scatter in (0.0, 0.002, 0.005):
        varied = dataclasses.replace(scene, scatter=np.full(scene.surface.n_points, scatter))
        settler = Settler(gripper, scene.surface, varied, config, obstacles=scene.obstacles)
        settled = settler.settle(fit, report)
        assert settled.settled is True and settled.report.collision_free
        outcomes[scatter] = (settled, settler)
    (smooth, _), (rough, rough_settler), (rougher, _) = (outcomes[s] for s in (0.0, 0.002, 0.005))
    assert smooth.within_bound is True and rough.within_bound is True
    assert rougher.within_bound is False
    assert np.array_equal(rougher.result.T_object_gripper, smooth.result.T_object_gripper)
    assert np.array_equal(rougher.result.q, smooth.result.q)
    T_rough, q_rough = rough.result.T_object_gripper, rough.result.q
    assert rough_settler.finger_depth.bound(T_rough, q_rough) <= 0.002
    assert rough.result.all_surfaces_in_contact
    # eased out of the true faces by about the extra margin the scatter asks for
    smooth_depth = _pad_depth(box, gripper, smooth.result.T_object_gripper, smooth.result.q)
    assert _pad_depth(box, gripper, T_rough, q_rough) < smooth_depth - 0.0005


def test_ranking_puts_settled_grasps_within_the_bound_first(box_scene):
    from isf.planning.planner import Grasp

    scene, _ = box_scene
    planned = isf.plan("flat-parallel", scene, samples=8, seed=2, rank="fit")
    best = next(g for g in planned.grasps if g.valid)
    within = dataclasses.replace(best, settled=True, within_bound=True, sample_index=2)
    beyond = dataclasses.replace(best, settled=True, within_bound=False, sample_index=0)
    unsettled = dataclasses.replace(best, settled=False, within_bound=None, sample_index=1)
    assert sorted([unsettled, beyond, within], key=Grasp.sort_key) == [within, beyond, unsettled]
    settled = [g for g in planned.grasps if g.settled]
    assert settled and all(g.within_bound in (True, False) for g in settled)
    assert all(g.within_bound is None for g in planned.grasps if not g.settled)
    order = [(g.settled is False, g.within_bound is False) for g in planned.grasps
             if g.valid and g.duplicate_of is None]
    assert order == sorted(order)
    on_object = isf.plan("flat-parallel", isf.open_object("shape:box"), samples=4, seed=2)
    assert all(g.within_bound is None for g in on_object.grasps)
