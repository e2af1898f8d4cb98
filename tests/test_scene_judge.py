"""The scene benchmark's ground-truth judge and simulator (``bench/scene_judge.py``,
``bench/scene_sim.py``) on hand-made cases with known answers.

The judge's cases place the bundled ``flat-parallel`` gripper, pointing down, around boxes
whose faces are where its pads are (or are not): the expected verdicts and penetration depths
follow from the box sizes and the gripper's URDF. The simulator's cases compare ray-cast depth
with the depth computed by hand, and its noise with the sensor model's sigma.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import isf
from isf.assets import YCBNotFoundError

# The bench modules import bench/_common.py, which would pin this process to one CPU.
os.environ.setdefault("ISF_BENCH_CPU", "none")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import scene_judge
import scene_sim

HEIGHT = 0.05  # m, box height
PAD_LOW, PAD_HIGH = 0.07, 0.09  # m, flat-parallel's pads span this range along its approach z


@pytest.fixture(scope="module")
def gripper():
    return isf.load_gripper("flat-parallel")


def box(name: str, size_x: float, y_low: float, y_high: float) -> scene_sim.SceneObject:
    """A box of height ``HEIGHT`` on the table, x in +-size_x/2, y in [y_low, y_high]."""
    mesh = trimesh.creation.box([size_x, y_high - y_low, HEIGHT])
    T = np.eye(4)
    T[:3, 3] = [0.0, (y_low + y_high) / 2, HEIGHT / 2]
    return scene_sim.SceneObject(name, mesh, T)


def downward(x: float = 0.0, y: float = 0.0, z: float = 0.11) -> np.ndarray:
    """``T_scene_gripper`` with the approach (gripper z) pointing down, root at (x, y, z): the
    pads then span z - 0.09 .. z - 0.07 and sit at scene y = -+q."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = [x, y, z]
    return T


def judge_of(gripper, *objects):
    return scene_judge.Judge(gripper, scene_sim.Scene(tuple(objects)))


def test_pads_on_the_faces_of_one_box_pass(gripper):
    judge = judge_of(gripper, box("box", 0.03, -0.02, 0.02))
    verdict = judge(downward(), [0.02])
    assert verdict.passed, verdict.describe()
    assert verdict.grasped == "box"
    assert verdict.penetration < 5e-4
    assert verdict.touched == {"left_pad": ("box",), "right_pad": ("box",)}


@pytest.mark.parametrize("depth", [0.001, 0.003, 0.006])
def test_pads_pressed_into_a_box_measure_the_depth(gripper, depth):
    judge = judge_of(gripper, box("box", 0.03, -0.02, 0.02))
    verdict = judge(downward(), [0.02 - depth])
    assert verdict.penetration == pytest.approx(depth, abs=3e-4)
    assert verdict.obstacle == "box"
    assert verdict.link in ("left_finger", "right_finger")
    assert verdict.passed == (depth <= scene_judge.PENETRATION_TOLERANCE), verdict.describe()
    if not verdict.passed:
        assert verdict.reason == "penetration"
        assert abs(abs(verdict.deepest_point[1]) - 0.02) < 1e-3  # on a gripped face


def test_a_gripper_inside_a_box_penetrates_deeply(gripper):
    judge = judge_of(gripper, box("box", 0.2, -0.1, 0.1))  # 20 cm wide: the fingers are inside
    verdict = judge(downward(z=0.12), [0.02])
    assert not verdict.passed
    assert verdict.reason == "penetration"
    assert verdict.penetration > 0.01
    assert verdict.link is not None


def test_a_gripper_beside_a_box_touches_nothing(gripper):
    judge = judge_of(gripper, box("box", 0.03, -0.02, 0.02))
    verdict = judge(downward(x=0.2), [0.02])
    assert not verdict.passed
    assert verdict.reason == "no contact"
    assert verdict.penetration == 0.0
    assert verdict.grasped is None
    assert all(gap == np.inf for gap in verdict.gaps.values())


def test_one_pad_on_the_box_and_one_in_the_air_is_no_grasp(gripper):
    judge = judge_of(gripper, box("box", 0.03, -0.02, 0.02))
    verdict = judge(downward(y=0.005), [0.025])  # pads at y = -0.02 (on a face) and y = 0.03
    assert verdict.reason == "no contact", verdict.describe()
    assert sorted(verdict.touched.values()) == [(), ("box",)]
    assert sorted(verdict.gaps.values()) == pytest.approx([0.0, 0.01], abs=2e-4)


@pytest.mark.parametrize("gap", [0.0, 0.0005])
def test_a_grasp_across_two_touching_boxes_is_scored_as_such(gripper, gap):
    judge = judge_of(gripper, box("a", 0.03, -0.02, -gap / 2), box("b", 0.03, gap / 2, 0.02))
    verdict = judge(downward(), [0.02])
    assert not verdict.passed
    assert verdict.reason == "two objects"
    assert verdict.penetration < 5e-4
    assert sorted(verdict.touched.values()) == [("a",), ("b",)]


def test_fingers_below_the_table_fail(gripper):
    judge = judge_of(gripper, box("box", 0.03, -0.02, 0.02))
    verdict = judge(downward(z=0.085), [0.02])  # fingertips at z = -5 mm
    assert not verdict.passed
    assert verdict.reason == "table"
    assert verdict.obstacle == scene_judge.TABLE
    assert verdict.penetration == pytest.approx(0.005, abs=1e-6)


def test_a_removed_object_no_longer_counts(gripper):
    scene = scene_sim.Scene((box("a", 0.03, -0.02, 0.0), box("b", 0.03, 0.0, 0.02)))
    verdict = scene_judge.Judge(gripper, scene.without("b"))(downward(), [0.02])
    assert verdict.reason == "no contact"
    assert sorted(verdict.touched.values()) == [(), ("a",)]


# ------------------------------------------------------------------ simulator


def test_the_depth_of_a_box_top_matches_the_pinhole_model():
    """A camera 0.6 m from the origin at 45 deg elevation; the ray of the central pixel (odd
    image size: cx, cy are whole pixels) meets the top of a 10 x 10 x 2 cm box at depth
    r - h * sqrt(2); a pixel aimed past the box sees the table."""
    r, h = 0.6, 0.02
    intr = scene_sim.Intrinsics.from_fov(321, 241, 60.0)
    eye = r * np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])
    camera = scene_sim.Camera(intr, scene_sim.look_at(eye, np.zeros(3)))
    T = np.eye(4)
    T[2, 3] = h / 2
    scene = scene_sim.Scene((scene_sim.SceneObject("box", trimesh.creation.box([0.1, 0.1, h]),
                                                   T),))
    view = scene_sim.render(scene, camera, scene_sim.SensorModel.ideal())
    assert view.depth[120, 160] == pytest.approx(r - h * np.sqrt(2), abs=1e-5)
    assert view.labels[120, 160] == 0 and view.labels[0, 160] == scene_sim.TABLE
    assert view.sees([0.0, 0.0, h]) and not view.sees([0.0, 0.0, 0.0])  # top seen, bottom hidden
    points = view.points()
    table = view.labels[view.depth > 0] == scene_sim.TABLE
    assert np.abs(points[table, 2]).max() < 1e-5
    assert np.abs(points[~table]).max(axis=0) == pytest.approx([0.05, 0.05, h], abs=1e-3)


def test_the_noise_on_a_plane_facing_the_camera_has_the_model_sigma():
    """A camera looking straight at a large wall 0.6 m away (incidence near 0): the depth error's
    std is the model's 1 mm (with 1 mm rounding, sqrt(1 + 1/12) mm)."""
    intr = scene_sim.Intrinsics.from_fov(160, 120, 30.0)
    wall = trimesh.creation.box([2.0, 0.01, 2.0])
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.605, 1.5]
    scene = scene_sim.Scene((scene_sim.SceneObject("wall", wall, T),))
    camera = scene_sim.Camera(intr, scene_sim.look_at([0.0, 0.0, 1.5], [0.0, 1.0, 1.5]))
    ideal = scene_sim.render(scene, camera, scene_sim.SensorModel.ideal())
    noisy = scene_sim.render(scene, camera, scene_sim.SensorModel(), rng=3)
    valid = noisy.depth > 0
    assert valid.mean() > 0.95
    error = noisy.depth[valid] - ideal.depth[valid]
    sensor = scene_sim.SensorModel()
    expected = np.sqrt(sensor.sigma(ideal.depth[valid], np.zeros(1)).mean() ** 2 + 1e-6 / 12)
    assert error.std() == pytest.approx(expected, rel=0.05)


def test_random_scenes_rest_on_the_table_without_interpenetration():
    try:
        objects = scene_sim.catalogue()
    except YCBNotFoundError as err:
        pytest.skip(f"YCB meshes absent: {err}")
    touching = 0
    for seed in range(3):
        scene = scene_sim.random_scene(objects, 6, seed, touch_probability=0.7)
        assert len(scene.objects) == 6
        for k, a in enumerate(scene.objects):
            assert a.posed_mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
            gaps = [scene_sim.mesh_gap(a, b) for b in scene.objects[k + 1:]]
            assert all(g > 0 for g in gaps)
            touching += sum(g < 1e-3 for g in gaps)
    assert touching >= 3
