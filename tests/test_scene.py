"""Scenes: depth images and clouds from a camera, the table, the unseen space, planning on them.

The depth images are ray cast by Open3D (tests/_depth_camera.py), independently of isf; the
expected answers are the geometry the images were made of.
"""

import numpy as np
import pytest
import trimesh
from _depth_camera import box_on_table, look_at, render_depth, table_mesh

import isf
from isf.collision.checker import CollisionChecker
from isf.exceptions import InvalidInputError, ObjectLoadError
from isf.scene import CameraIntrinsics, SceneView, UnseenSpace, ViewDepth, find_table, load_scene

EYE = (0.45, -0.35, 0.5)


@pytest.fixture(scope="module")
def box_view():
    """A 6 x 6 x 10 cm box on a table, seen from above and the side, 1 mm depth noise."""
    box = box_on_table((0.06, 0.06, 0.10))
    T = look_at(EYE, (0.0, 0.0, 0.05))
    depth, intrinsics = render_depth([table_mesh(), box], T, noise=0.001)
    return depth, intrinsics, T, box


def _camera_point(intrinsics, u, v, z):
    """The camera-frame point of pixel (u, v) at depth z (the pinhole model, written out)."""
    return np.array([(u - intrinsics["cx"]) * z / intrinsics["fx"],
                     (v - intrinsics["cy"]) * z / intrinsics["fy"], z])


def test_unseen_space_is_the_space_behind_each_observed_pixel():
    depth = np.full((60, 80), 0.5)  # a wall 0.5 m in front of the camera
    intrinsics = CameraIntrinsics(100.0, 100.0, 39.5, 29.5, 80, 60)
    unseen = UnseenSpace((ViewDepth.from_depth(depth, intrinsics, np.eye(4)),))
    at = {"fx": 100.0, "fy": 100.0, "cx": 39.5, "cy": 29.5}
    behind = _camera_point(at, 10, 20, 0.55)
    front = _camera_point(at, 10, 20, 0.45)
    outside = _camera_point(at, -30, 20, 0.9)  # outside the image: no camera saw it
    np.testing.assert_allclose(unseen.depth_inside(np.array([behind, front, outside])),
                               [0.05, 0.0, 0.0], atol=1e-12)


def test_a_finger_behind_the_observed_surface_collides_and_in_front_does_not(box_view):
    depth, intrinsics, T, box = box_view
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table="auto")
    gripper = isf.load_gripper("paper-parallel")
    checker = CollisionChecker(gripper, scene.surface, obstacles=scene.obstacles,
                               hidden=scene.unseen)
    sight = np.array([0.0, 0.0, 0.05]) - T[:3, 3]
    sight /= np.linalg.norm(sight)
    # The box's near face is about 4 cm in front of its centre along the line of sight: a
    # gripper 12 cm beyond the centre (hidden behind the box, above the table) is in the
    # unseen space; the same gripper 25 cm before the centre is in seen free space.
    pose = np.eye(4)
    pose[:3, 3] = np.array([0.0, 0.0, 0.05]) + 0.12 * sight + [0, 0, 0.04]
    hidden = checker.check(pose, gripper.q_initial)
    pose[:3, 3] = np.array([0.0, 0.0, 0.05]) - 0.25 * sight
    seen = checker.check(pose, gripper.q_initial)
    assert not hidden.collision_free and hidden.obstacle == "unseen"
    assert seen.collision_free
    # ground truth: the hidden pose lies in the box's shadow, the box does not contain it
    assert not box.contains([pose[:3, 3]])[0]


def test_table_auto_finds_a_tilted_table_within_2_mm_and_1_degree():
    tilt = trimesh.transformations.rotation_matrix(np.radians(4.0), [1, 0.3, 0]) @ \
        trimesh.transformations.translation_matrix([0, 0, 0.03])
    meshes = [table_mesh(), box_on_table((0.05, 0.08, 0.12), (0.05, 0.02)),
              box_on_table((0.07, 0.04, 0.05), (-0.08, -0.05))]
    for mesh in meshes:
        mesh.apply_transform(tilt)
    T = look_at(EYE, (0.0, 0.0, 0.05))
    depth, intrinsics = render_depth(meshes, T, noise=0.001, seed=3)
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table="auto")
    normal = tilt[:3, :3] @ [0, 0, 1]
    offset = normal @ tilt[:3, 3]
    angle = np.degrees(np.arccos(np.clip(scene.table.normal @ normal, -1, 1)))
    assert angle < 1.0
    assert abs(scene.table.offset - offset) < 0.002
    # the table is gone from the surface: every point lies above it
    assert (scene.table.height(scene.surface.points) > 0.004).all()


def test_find_table_needs_a_dominant_plane():
    rng = np.random.default_rng(0)
    with pytest.raises(ObjectLoadError, match="no plane"):
        find_table(rng.normal(size=(2000, 3)), np.zeros((1, 3)))


def test_normals_face_the_camera_and_follow_the_faces(box_view):
    depth, intrinsics, T, _ = box_view
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table=0.0)
    points, normals = scene.surface.points, scene.surface.normals
    assert (np.einsum("ij,ij->i", normals, T[:3, 3] - points) > 0).all()
    top = (points[:, 2] > 0.097) & (np.abs(points[:, :2]) < 0.022).all(axis=1)
    assert top.sum() > 50
    assert np.median(normals[top] @ [0, 0, 1]) > np.cos(np.radians(5))


def test_a_depth_image_and_the_same_cloud_give_the_same_plan(box_view, tmp_path):
    depth, intrinsics, T, _ = box_view
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    cloud = np.column_stack([(u - intrinsics["cx"]) * z / intrinsics["fx"],
                             (v - intrinsics["cy"]) * z / intrinsics["fy"], z])
    np.save(tmp_path / "cloud.npy", cloud)
    np.save(tmp_path / "depth.npy", depth)
    sized = CameraIntrinsics(**intrinsics, width=depth.shape[1], height=depth.shape[0])
    from_depth = load_scene(tmp_path / "depth.npy", intrinsics=intrinsics, T_scene_camera=T,
                            table="auto")
    from_cloud = load_scene(tmp_path / "cloud.npy", intrinsics=sized, T_scene_camera=T,
                            table="auto")
    np.testing.assert_allclose(from_cloud.surface.points, from_depth.surface.points, atol=1e-12)
    gripper = isf.load_gripper("paper-parallel")
    a = isf.plan(gripper, from_depth, samples=6, seed=1)
    b = isf.plan(gripper, from_cloud, samples=6, seed=1)
    for x, y in zip(a.grasps, b.grasps):
        np.testing.assert_allclose(x.T_object_gripper, y.T_object_gripper, atol=1e-9)
        assert x.collision_free == y.collision_free


def test_a_png_depth_image_in_millimetres(box_view, tmp_path):
    from PIL import Image

    depth, intrinsics, T, _ = box_view
    millimetres = np.rint(depth * 1000).astype(np.uint16)
    Image.fromarray(millimetres).save(tmp_path / "depth.png")
    scene = load_scene(tmp_path / "depth.png", intrinsics=intrinsics, T_scene_camera=T,
                       table="auto")
    assert abs(scene.table.offset) < 0.002
    assert scene.surface.points[:, 2].max() == pytest.approx(0.10, abs=0.004)


@pytest.mark.parametrize("intrinsics, message", [
    ({"fx": 0.0, "fy": 300.0, "cx": 160.0, "cy": 120.0}, "fx and fy must be > 0"),
    ({"fx": float("nan"), "fy": 300.0, "cx": 160.0, "cy": 120.0}, "finite"),
    ({"fx": 300.0, "fy": 300.0}, "need the keys"),
    ("300,300,abc,120", "not numbers"),
    (None, "needs the camera intrinsics"),
])
def test_bad_intrinsics_are_refused_in_one_line(box_view, intrinsics, message):
    depth = box_view[0]
    with pytest.raises(InvalidInputError, match=message) as info:
        load_scene(depth, intrinsics=intrinsics)
    assert "\n" not in str(info.value)


def test_an_empty_scene_and_a_scene_with_nothing_above_the_table(box_view):
    depth, intrinsics, T, _ = box_view
    with pytest.raises(ObjectLoadError, match="no valid pixel"):
        load_scene(np.zeros((240, 320)), intrinsics=intrinsics)
    with pytest.raises(ObjectLoadError, match="above the table"):
        load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table=0.5)


def test_a_camera_pose_that_is_not_rigid_is_refused(box_view):
    depth, intrinsics, T, _ = box_view
    scaled = T.copy()
    scaled[:3, :3] *= 1.01
    with pytest.raises(InvalidInputError, match="not rigid"):
        load_scene(depth, intrinsics=intrinsics, T_scene_camera=scaled)
    mirrored = T.copy()
    mirrored[:3, 0] *= -1
    with pytest.raises(InvalidInputError, match="not rigid"):
        load_scene(depth, intrinsics=intrinsics, T_scene_camera=mirrored)
    with pytest.raises(InvalidInputError, match="needs 16"):
        load_scene(depth, intrinsics=intrinsics, T_scene_camera="1,0,0")


def test_a_cloud_behind_the_camera_needs_its_frame(box_view):
    depth, intrinsics, T, _ = box_view
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T)
    with pytest.raises(ObjectLoadError, match="behind the camera"):
        load_scene(scene.surface.points - [0, 0, 1.0])
    # the same points declared to be in the scene frame load, seen from the camera pose
    again = load_scene(SceneView(scene.surface.points, T_scene_camera=T, cloud_frame="scene"))
    assert again.surface.n_points > 0.8 * scene.surface.n_points


def test_two_views_free_what_either_camera_saw(box_view):
    depth, intrinsics, T, box = box_view
    opposite = look_at((-0.45, 0.35, 0.5), (0.0, 0.0, 0.05))
    depth2, _ = render_depth([table_mesh(), box], opposite, noise=0.001, seed=1)
    one = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table="auto")
    two = load_scene([SceneView(depth, intrinsics, T), SceneView(depth2, intrinsics, opposite)],
                     table="auto")
    # a point just behind the box's far face, as the first camera sees it: unseen by the first
    # camera, seen (in front of the box) by the second
    sight = np.array([0.0, 0.0, 0.05]) - T[:3, 3]
    sight /= np.linalg.norm(sight)
    point = np.array([[0.0, 0.0, 0.05]]) + 0.06 * sight
    assert one.unseen.depth_inside(point)[0] > 0.02
    assert two.unseen.depth_inside(point)[0] == 0.0
    assert two.surface.n_points > one.surface.n_points


def test_grasp_ranking_puts_one_piece_before_two():
    import dataclasses

    from isf.planning.planner import Grasp

    planned = isf.plan("paper-parallel", isf.open_object("shape:cylinder"), samples=4, seed=0)
    best = next(g for g in planned.grasps if g.valid)
    one = dataclasses.replace(best, pieces=1, sample_index=1)
    two = dataclasses.replace(best, pieces=2, sample_index=0)
    assert sorted([two, one], key=Grasp.sort_key) == [one, two]
    assert one.valid and not two.valid
    assert best.pieces is None and best.one_piece  # on an object there are no pieces


def test_the_regret_sampler_spreads_more_centres_over_a_scene(box_view):
    from isf.samplers.regret import RegretSampler

    depth, intrinsics, T, _ = box_view
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table="auto")
    gripper = isf.load_gripper("paper-parallel")
    points, _ = gripper.contact_points(gripper.q_initial)
    centres = [points[gripper.point_surface == k].mean(axis=0) for k in range(2)]
    opening = np.abs(centres[0] - centres[1]).max()
    area = scene.surface.n_points * scene.surface.spacing**2
    expected = int(np.clip(round(area / (0.5 * opening) ** 2), 6, 30))
    on_scene, on_object = RegretSampler(), RegretSampler()
    on_scene.reset(scene.surface, gripper, np.random.default_rng(0))
    on_object.reset(isf.open_object("shape:cylinder"), gripper, np.random.default_rng(0))
    assert on_scene.k == expected > 6
    assert on_object.k == 6 and len(on_object.centres) == 6


def test_a_scene_plan_file_records_the_cameras_and_the_table(box_view, tmp_path):
    import json

    import jsonschema

    from isf.planning.plan_json import SCHEMA_PATH, write_plan_json

    depth, intrinsics, T, _ = box_view
    scene = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table="auto")
    result = isf.plan("paper-parallel", scene, samples=4, seed=0)
    path = write_plan_json(result, tmp_path / "scene.json")
    data = json.loads(path.read_text())
    jsonschema.validate(data, json.loads(SCHEMA_PATH.read_text()))
    np.testing.assert_allclose(data["scene"]["T_scene_camera"][0], T)
    np.testing.assert_allclose(data["scene"]["table"]["normal"], scene.table.normal)
    assert all(isinstance(g["pieces"], int) for g in data["grasps"])
    assert [g["valid"] for g in data["grasps"]] == [g.valid for g in result.grasps]


def _isf(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "isf", *args], capture_output=True, text=True,
                          timeout=600)


def test_isf_plan_on_a_depth_image_gives_the_library_plan(box_view, tmp_path):
    import json

    depth, intrinsics, T, _ = box_view
    np.save(tmp_path / "depth.npy", depth)
    np.savetxt(tmp_path / "pose.txt", T)
    out = tmp_path / "grasps.json"
    proc = _isf("plan", "--gripper", "paper-parallel", "--scene", str(tmp_path / "depth.npy"),
                "--intrinsics", ",".join(str(intrinsics[k]) for k in ("fx", "fy", "cx", "cy")),
                "--camera-pose", str(tmp_path / "pose.txt"), "--table", "auto",
                "--samples", "6", "--seed", "2", "--out", str(out))
    assert proc.returncode in (0, 1), proc.stderr
    data = json.loads(out.read_text())
    library = isf.plan("paper-parallel", load_scene(depth, intrinsics=intrinsics,
                                                    T_scene_camera=np.loadtxt(tmp_path / "pose.txt"),
                                                    table="auto"), samples=6, seed=2)
    np.testing.assert_allclose([g["T_object_gripper"] for g in data["grasps"]],
                               [g.T_object_gripper for g in library.grasps], atol=1e-9)
    assert proc.returncode == (0 if library.stats.valid else 1)


@pytest.mark.parametrize("extra, message", [
    (["--intrinsics", "0,300,160,120"], "fx and fy must be > 0"),
    ([], "needs the camera intrinsics"),
    (["--intrinsics", "300,300,160,120", "--camera-pose", "2,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1"],
     "not rigid"),
    (["--intrinsics", "300,300,160,120", "--table", "high"], "must be a height in metres or 'auto'"),
    (["--intrinsics", "300,300,160,120", "--object", "shape:cylinder"], "not both"),
])
def test_isf_plan_scene_mistakes_exit_2_in_one_line(box_view, tmp_path, extra, message):
    np.save(tmp_path / "depth.npy", box_view[0])
    out = tmp_path / "grasps.json"
    proc = _isf("plan", "--gripper", "paper-parallel", "--scene", str(tmp_path / "depth.npy"),
                "--out", str(out), *extra)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_table_auto_and_camera_options_need_a_scene(tmp_path):
    for extra, message in ((["--table", "auto"], "'auto' needs --scene"),
                           (["--intrinsics", "1,1,1,1"], "describe a --scene")):
        proc = _isf("plan", "--gripper", "paper-parallel", "--object", "shape:cylinder",
                    "--out", str(tmp_path / "x.json"), *extra)
        assert proc.returncode == 2 and message in proc.stderr, proc.stderr


def test_camera_keywords_beside_views_are_refused_in_one_line(box_view):
    depth, intrinsics, T, _ = box_view
    view = SceneView(depth, intrinsics, T)
    with pytest.raises(InvalidInputError, match="T_scene_camera belong in each SceneView"):
        load_scene(view, T_scene_camera=T)
    with pytest.raises(InvalidInputError, match="cloud_frame belong in each SceneView"):
        load_scene([view], cloud_frame="scene")
    assert load_scene(view, cloud_frame="camera").surface.n_points > 0


def test_isolated_stray_points_leave_the_surface_and_the_box_stays(box_view):
    # Flying pixels: 24 table pixels, 8 px apart and away from the box, pulled 3 cm towards the
    # camera (2-3 cm above the table), each alone in the air. They leave the surface ISF fits;
    # the box's faces keep their points.
    depth, intrinsics, T, _ = box_view
    clean = load_scene(depth, intrinsics=intrinsics, T_scene_camera=T, table=0.0)
    strays = depth.copy()
    rows, cols = np.meshgrid(np.arange(20, 230, 8), np.arange(10, 310, 8), indexing="ij")
    lifted = []
    for v, u in zip(rows.ravel(), cols.ravel()):
        point = T[:3, :3] @ _camera_point(intrinsics, u, v, depth[v, u]) + T[:3, 3]
        if depth[v, u] > 0 and abs(point[2]) < 0.003 and np.abs(point[:2]).max() > 0.1:
            strays[v, u] -= 0.03
            lifted.append(T[:3, :3] @ _camera_point(intrinsics, u, v, strays[v, u]) + T[:3, 3])
        if len(lifted) == 24:
            break
    lifted = np.array(lifted)
    assert len(lifted) == 24 and (lifted[:, 2] > 0.01).all()
    scene = load_scene(strays, intrinsics=intrinsics, T_scene_camera=T, table=0.0)
    gaps = np.linalg.norm(scene.surface.points[:, None] - lifted[None], axis=2).min(axis=0)
    assert (gaps > 0.01).all()  # no stray is left
    assert scene.surface.n_points == pytest.approx(clean.surface.n_points, abs=5)
