"""The scene's noise estimate and the settling of grasps out of the observed surface, checked
against independent geometry: an analytic noise law and Open3D's signed distances to the true
meshes a test camera (Open3D ray casting) observed."""

from __future__ import annotations

import numpy as np
import pytest
from _depth_camera import box_on_table, look_at, render_depth, table_mesh
from _open3d import import_open3d
from scipy import stats

import isf
from isf.collision.checker import CollisionChecker
from isf.fitting.engine import score_fit
from isf.scene import NOISE_MARGIN, Settler, contact_allowance, load_scene

BOX = (0.05, 0.04, 0.10)  # x, y, z extents, m: the fingers close on the faces y = +-0.02


@pytest.mark.parametrize("sigma", [0.0005, 0.001])
def test_scene_noise_is_the_depth_noise_of_a_flat_surface(sigma):
    # A camera straight above a plane 0.5 m away, its central pixels kept (rays within 12 degrees
    # of the axis; 3.3 mm apart, so the nearest neighbours are picked by position, not by
    # noise): the depth noise is along the plane's normal. The residual sum of squares
    # about a least-squares plane through k = 16 points is sigma^2 chi^2(k - 3), so the median
    # over the points of their RMS residual is sigma * sqrt(median chi^2(13) / 16).
    T = look_at((0.0, 0.0, 0.5), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    depth, intrinsics = render_depth([table_mesh()], T, f=150.0, noise=sigma, seed=3)
    central = np.zeros_like(depth)
    central[90:150, 130:190] = depth[90:150, 130:190]
    scene = load_scene(central, intrinsics=intrinsics, T_scene_camera=T, voxel_size=0.0005)
    expected = sigma * np.sqrt(stats.chi2.median(13) / 16)
    assert scene.noise == pytest.approx(expected, rel=0.08)


def test_a_noise_free_surface_has_no_noise():
    T = look_at((0.0, 0.0, 0.5), (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    depth, intrinsics = render_depth([table_mesh()], T)
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, voxel_size=0.0005)
    assert scene.noise < 2e-5


@pytest.fixture(scope="module")
def two_sided_box():
    """A box on a table seen by two noisy cameras, one on each side the fingers close on."""
    box = box_on_table(BOX)
    return _seen_from_both_sides(box, 0.05), box


def _seen_from_both_sides(box, target_height: float):
    """The scene of ``box`` on the table seen by two cameras with 1 mm noise, at y = +-0.45 m,
    looking at the point ``target_height`` metres above the origin."""
    views = []
    for k, side in enumerate((1.0, -1.0)):
        T = look_at((0.05, side * 0.45, 0.45), (0.0, 0.0, target_height))
        depth, intrinsics = render_depth([table_mesh(), box], T, noise=0.001, seed=k)
        views.append(isf.SceneView(depth, intrinsics=intrinsics, T_scene_camera=T))
    return load_scene(views, table="auto")


def _pads_into(box, gripper, T, q) -> tuple[float, list[float]]:
    """Deepest pad point inside the true box (m, > 0 inside) and each pad's distance to it
    (Open3D signed distances, independent of isf's collision code)."""
    o3d = import_open3d()
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(np.asarray(box.vertices, np.float32)),
                     o3d.core.Tensor(np.asarray(box.faces, np.uint32)))
    points, _ = gripper.contact_points(q)
    scene_points = points @ T[:3, :3].T + T[:3, 3]
    signed = rc.compute_signed_distance(
        o3d.core.Tensor(scene_points.astype(np.float32))).numpy().astype(float)
    gaps = [float(np.abs(signed[gripper.point_link == k]).min())
            for k in range(len(gripper.contact_links))]
    return float(max(0.0, -signed.min())), gaps


def _pressed_grasp(gripper, press: float) -> tuple[np.ndarray, np.ndarray]:
    """flat-parallel from above, its pads (y = +-q, 7-9 cm along the approach) 2-4 cm below the
    box's top, each pressed ``press`` metres into a face y = +-0.02."""
    T = np.eye(4)
    T[:3, :3] = np.diag([-1.0, 1.0, -1.0])  # approach (gripper +z) straight down
    T[:3, 3] = (0.0, 0.0, BOX[2] + 0.05)
    return T, np.array([BOX[1] / 2 - press])


def test_settling_moves_pressed_fingers_out_of_the_true_surface(two_sided_box):
    scene, box = two_sided_box
    gripper = isf.load_gripper("flat-parallel")
    T, q = _pressed_grasp(gripper, 0.0015)
    before, _ = _pads_into(box, gripper, T, q)
    assert before == pytest.approx(0.0015, abs=1e-5)
    config = isf.FitConfig()
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    report = checker.check(T, q)
    assert report.collision_free  # within the planner's 2 mm against the observed surface
    fit = score_fit(gripper, scene.surface, T, q, config, isf.FitStatus.CONVERGED, (), 0.0)
    settler = Settler(gripper, scene.surface, scene, config, obstacles=scene.obstacles)
    assert settler.allowance == pytest.approx(max(0.0, 0.002 - NOISE_MARGIN * scene.noise))
    settled = settler.settle(fit, report)
    assert settled.settled and settled.report.collision_free
    assert settled.report.penetration <= settler.allowance
    after, gaps = _pads_into(box, gripper, settled.result.T_object_gripper, settled.result.q)
    assert after < 0.0008  # out of the true faces but for the sensor's noise
    assert max(gaps) < 0.002  # and both pads still touch the box
    assert settled.result.all_surfaces_in_contact


def test_one_finger_pressing_alone_moves_the_hand_off_it(two_sided_box):
    # The hand 1.5 mm off centre: the left pad (scene y = +q) 1.5 mm inside the face y = 0.02,
    # the right one 1.5 mm short of y = -0.02. Opening would lose the right pad's contact;
    # shifting the hand back puts both on their faces.
    scene, box = two_sided_box
    gripper = isf.load_gripper("flat-parallel")
    T, q = _pressed_grasp(gripper, 0.0)
    T[1, 3] -= 0.0015
    before, gaps = _pads_into(box, gripper, T, q)
    assert before == pytest.approx(0.0015, abs=1e-5) and max(gaps) == pytest.approx(0.0015, abs=1e-5)
    config = isf.FitConfig()
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    fit = score_fit(gripper, scene.surface, T, q, config, isf.FitStatus.CONVERGED, (), 0.0)
    settled = Settler(gripper, scene.surface, scene, config,
                      obstacles=scene.obstacles).settle(fit, checker.check(T, q))
    assert settled.settled
    after, gaps = _pads_into(box, gripper, settled.result.T_object_gripper, settled.result.q)
    assert after < 0.0008 and max(gaps) < 0.0012


def test_a_grasp_that_collides_is_left_alone(two_sided_box):
    scene, _ = two_sided_box
    gripper = isf.load_gripper("flat-parallel")
    T, q = _pressed_grasp(gripper, 0.008)
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    report = checker.check(T, q)
    assert not report.collision_free
    config = isf.FitConfig()
    fit = score_fit(gripper, scene.surface, T, q, config, isf.FitStatus.CONVERGED, (), 0.0)
    settled = Settler(gripper, scene.surface, scene, config).settle(fit, report)
    assert settled.settled is None and settled.result is fit and settled.report is report


def test_contact_allowance_shrinks_with_the_noise(two_sided_box):
    scene, _ = two_sided_box
    assert contact_allowance(scene, 0.002) == pytest.approx(0.002 - NOISE_MARGIN * scene.noise)
    assert contact_allowance(scene, 0.0) == 0.0


def test_plans_on_scenes_are_settled_and_plans_on_objects_are_not(two_sided_box):
    scene, box = two_sided_box
    gripper = isf.load_gripper("flat-parallel")
    on_scene = isf.plan(gripper, scene, samples=8, seed=2)
    free = [g for g in on_scene.grasps if g.collision_free]
    assert free and all(g.settled is not None for g in free)
    assert all(g.settled is None for g in on_scene.grasps if not g.collision_free)
    ranked = [g.settled for g in on_scene.grasps if g.valid]
    assert ranked == sorted(ranked, reverse=True)  # settled grasps first
    allowance = contact_allowance(scene, 0.002)
    assert all(g.collision.penetration <= allowance for g in free if g.settled)
    on_object = isf.plan(gripper, isf.open_object("shape:box"), samples=4, seed=2)
    assert all(g.settled is None for g in on_object.grasps)


def test_fingertips_in_the_table_back_off_instead_of_opening():
    # A box 6 cm tall seen from both sides; flat-parallel from above, its pads on the faces
    # y = +-0.02 (unpressed), its fingertips (9 cm along the approach) 1.5 mm below the table.
    # Opening the fingers leaves the tips as deep and takes the pads off the faces; backing off
    # lifts the tips out and keeps the pads on.
    low = (BOX[0], BOX[1], 0.06)
    box = box_on_table(low)
    scene = _seen_from_both_sides(box, 0.03)
    gripper = isf.load_gripper("flat-parallel")
    T, q = _pressed_grasp(gripper, 0.0)
    T[2, 3] = 0.09 - 0.0015
    config = isf.FitConfig()
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    report = checker.check(T, q)
    assert report.collision_free and report.penetration > 0.001
    fit = score_fit(gripper, scene.surface, T, q, config, isf.FitStatus.CONVERGED, (), 0.0)
    settler = Settler(gripper, scene.surface, scene, config, obstacles=scene.obstacles)
    settled = settler.settle(fit, report)
    assert settled.settled
    T_after, q_after = settled.result.T_object_gripper, settled.result.q
    poses = gripper.link_poses(q_after)
    lowest = min(float((np.asarray(g.vertices) @ (T_after @ poses[g.link])[:3, :3].T
                        + (T_after @ poses[g.link])[:3, 3])[:, 2].min())
                 for g in gripper.geometries)
    assert -settler.allowance - 0.0006 <= lowest < 0.0  # out of the true table but for its fit
    _, gaps = _pads_into(box, gripper, T_after, q_after)
    assert max(gaps) < 0.002  # the pads still touch the faces
