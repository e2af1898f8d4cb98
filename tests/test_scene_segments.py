"""The pieces of a scene surface (``isf/scene/segments.py``) on depth images of known scenes.

The scenes are boxes and a can standing on a table at z = 0 (scene frame: metres, z up). Their
depth images come from an analytic ray caster written here (ray-box slabs, ray-cylinder
quadratic, ray-plane), with 1 mm Gaussian depth noise, and go through :func:`isf.load_scene` as
a camera's depth would. Which object each surface point belongs to follows from the boxes'
extents, so the expected pieces are known without the segmenter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from _depth_camera import look_at

import isf
from isf.exceptions import InvalidInputError
from isf.scene import SceneView, load_scene, segment_surface

FX, WIDTH, HEIGHT = 300.0, 320, 240  # pixels
NOISE = 0.001  # m, depth noise
# m: the tall box spans x in [-0.04, 0], the low one [0, 0.035] and 1 cm more than the tall on
# either side in y
TALL_X, SPLIT_X, LOW_X = -0.04, 0.0, 0.035


@dataclass(frozen=True)
class Box:
    """An axis-aligned box, corners ``low`` and ``high`` (scene frame, metres)."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]

    def hit(self, origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """Ray parameter of the first hit of each ray ``origin + t * ray`` (inf: a miss)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (np.array(self.low) - origin) / rays
            t2 = (np.array(self.high) - origin) / rays
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        return np.where((far >= near) & (near > 0), near, np.inf)


@dataclass(frozen=True)
class Can:
    """A vertical cylinder standing on z = 0: axis through ``centre`` (x, y), metres."""

    centre: tuple[float, float]
    radius: float
    height: float

    def hit(self, origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """Ray parameter of the first hit of each ray (inf: a miss)."""
        o = origin[:2] - np.array(self.centre)
        d = rays[:, :2]
        a, b, c = (d * d).sum(axis=1), 2 * d @ o, o @ o - self.radius**2
        root = b * b - 4 * a * c
        with np.errstate(invalid="ignore"):
            side = (-b - np.sqrt(root)) / (2 * a)
        z = origin[2] + side * rays[:, 2]
        side = np.where((root >= 0) & (side > 0) & (z >= 0) & (z <= self.height), side, np.inf)
        with np.errstate(divide="ignore"):
            top = (self.height - origin[2]) / rays[:, 2]
        xy = origin[:2] + top[:, None] * d - np.array(self.centre)
        top = np.where((top > 0) & ((xy * xy).sum(axis=1) <= self.radius**2), top, np.inf)
        return np.minimum(side, top)


def camera(eye) -> np.ndarray:
    """``T_scene_camera`` of a camera at ``eye`` looking at the scene's centre (metres)."""
    return look_at(eye, (0.0, 0.0, 0.04))


def depth_view(shapes, T_scene_camera: np.ndarray, seed: int) -> SceneView:
    """A noisy depth image of ``shapes`` on the table z = 0 seen from ``T_scene_camera``."""
    u, v = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    local = np.stack([(u - (WIDTH - 1) / 2) / FX, (v - (HEIGHT - 1) / 2) / FX,
                      np.ones(u.shape)], axis=-1).reshape(-1, 3)
    rays = local @ T_scene_camera[:3, :3].T  # camera z = 1: the ray parameter is the depth
    origin = T_scene_camera[:3, 3]
    with np.errstate(divide="ignore"):
        table = np.where(rays[:, 2] < 0, -origin[2] / rays[:, 2], np.inf)
    depth = np.min([table] + [shape.hit(origin, rays) for shape in shapes], axis=0)
    depth = np.where(np.isfinite(depth), depth, 0.0)
    depth[depth > 0] += np.random.default_rng(seed).normal(0.0, NOISE, int((depth > 0).sum()))
    return SceneView(depth.reshape(HEIGHT, WIDTH),
                     intrinsics=dict(fx=FX, fy=FX, cx=(WIDTH - 1) / 2, cy=(HEIGHT - 1) / 2),
                     T_scene_camera=T_scene_camera)


TALL = Box((TALL_X, -0.03, 0.0), (SPLIT_X, 0.03, 0.10))
LOW = Box((SPLIT_X, -0.04, 0.0), (LOW_X, 0.04, 0.06))
CAN = Can((0.0, 0.0), 0.035, 0.12)
VIEWS = [(0.30, -0.35, 0.40), (0.45, 0.10, 0.45), (-0.20, 0.40, 0.35), (-0.40, -0.25, 0.50)]


def share_in_largest(labels: np.ndarray) -> float:
    """Share of ``labels`` in their most common value."""
    return np.bincount(labels).max() / len(labels)


@pytest.mark.parametrize("eye", VIEWS)
def test_touching_boxes_of_different_heights_split(eye):
    scene = load_scene(depth_view([TALL, LOW], camera(eye), seed=1), table=0.0)
    points, labels = scene.surface.points, scene.segments.labels
    # away from the crease (the 2 cm where either box's normals may blur), by the boxes' extents
    tall, low = points[:, 0] < SPLIT_X - 0.01, points[:, 0] > SPLIT_X + 0.01
    tall_piece = np.bincount(labels[tall]).argmax()
    low_piece = np.bincount(labels[low]).argmax()
    assert tall_piece != low_piece
    assert np.mean(labels[low] == tall_piece) < 0.05
    assert np.mean(labels[tall] == low_piece) < 0.05
    assert share_in_largest(labels[tall]) > 0.8
    assert share_in_largest(labels[low]) > 0.8


@pytest.mark.parametrize("shape", [TALL, CAN], ids=["box", "can"])
@pytest.mark.parametrize("eye", VIEWS[:2])
def test_a_single_object_stays_one_piece(shape, eye):
    scene = load_scene(depth_view([shape], camera(eye), seed=2), table=0.0)
    assert share_in_largest(scene.segments.labels) > 0.9


def test_pieces_are_numbered_by_decreasing_size():
    scene = load_scene(depth_view([TALL, LOW], camera(VIEWS[0]), seed=3), table=0.0)
    sizes = np.bincount(scene.segments.labels)
    assert scene.segments.count == len(sizes)
    assert (np.diff(sizes) <= 0).all()
    again = segment_surface(scene.surface.points, scene.surface.normals, scene.surface.spacing)
    assert np.array_equal(again, scene.segments.labels)


def test_a_gap_separates_and_an_empty_surface_has_no_piece():
    grid = np.stack(np.meshgrid(np.arange(20), np.arange(20), [0]), -1).reshape(-1, 3) * 0.002
    points = np.concatenate([grid, grid + [0.06, 0.0, 0.0]])  # two flat patches 2 cm apart
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    labels = segment_surface(points, normals, 0.002)
    assert len(set(labels[:400])) == 1 and len(set(labels[400:])) == 1
    assert labels[0] != labels[400]
    assert segment_surface(np.zeros((0, 3)), np.zeros((0, 3)), 0.002).shape == (0,)


def test_mismatched_normals_or_a_bad_spacing_are_one_line_errors():
    points = np.zeros((5, 3))
    with pytest.raises(InvalidInputError, match="one shape"):
        segment_surface(points, np.zeros((4, 3)), 0.002)
    with pytest.raises(InvalidInputError, match="spacing"):
        segment_surface(points, points, 0.0)


@pytest.fixture(scope="module")
def gripper():
    return isf.load_gripper("flat-parallel")


def pads_across(gripper, x_low: float, x_high: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat-parallel grasp from above whose two pads (at gripper y = -+q) lie flat on the
    planes x = x_low and x = x_high, from 2 cm above the table up: ``(T_scene_gripper, q)``."""
    points, _ = gripper.contact_points(np.array([0.0]))
    T = np.eye(4)  # gripper x, y, z along scene y, x, -z: approach down, closing along x
    T[:3, :3] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]
    T[:3, 3] = [(x_low + x_high) / 2, 0.0, 0.02 + points[:, 2].max()]
    q = np.array([(x_high - x_low) / 2])
    placed, _ = gripper.contact_points(q)
    placed = placed @ T[:3, :3].T + T[:3, 3]
    pad_x = sorted(placed[gripper.point_surface == k, 0].mean() for k in range(2))
    assert np.allclose(pad_x, [x_low, x_high]) and np.isclose(placed[:, 2].min(), 0.02)
    return T, q


def seen_from_both_sides(shapes) -> isf.scene.Scene:
    """The scene of ``shapes`` seen by two cameras, one on each side of the plane x = 0."""
    views = [depth_view(shapes, camera(eye), seed=k)
             for k, eye in enumerate([(-0.40, 0.10, 0.30), (0.40, -0.10, 0.30)])]
    return load_scene(views, table=0.0)


# a contact point touches the surface within the depth noise and half a point spacing
CONTACT = 0.003


def test_a_grasp_across_two_touching_boxes_touches_two_pieces(gripper):
    scene = seen_from_both_sides([TALL, LOW])
    T, q = pads_across(gripper, TALL_X, LOW_X)
    assert scene.segments.touched(gripper, T, q, CONTACT) == 2


def test_a_grasp_of_one_box_touches_one_piece_and_a_grasp_in_the_air_none(gripper):
    scene = seen_from_both_sides([TALL])
    T, q = pads_across(gripper, TALL_X, SPLIT_X)
    assert scene.segments.touched(gripper, T, q, CONTACT) == 1
    T[2, 3] += 0.2
    assert scene.segments.touched(gripper, T, q, CONTACT) == 0
