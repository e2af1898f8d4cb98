"""The convex parts the physics test collides (isf.simulation.object_body) stay on the mesh.

Ground truth is analytic: a 10 cm block with a groove 3 mm deep across its top face. Its hull
fills the groove (3 mm above the mesh there); its parts may stand off the mesh by about
``PART_TOLERANCE`` only, and the points of the parts outside the block are exactly those in
the groove, whose distance from the block is known in closed form.
"""

from __future__ import annotations

import importlib
import importlib.util

import numpy as np
import pytest

pytest.importorskip("mujoco")
if importlib.util.find_spec("coacd") is None:  # looked up, not imported: see isf.simulation.object_body
    pytest.skip("coacd is not installed (pip install 'isf[sim]')", allow_module_level=True)

import trimesh

from isf.simulation.object_body import PART_TOLERANCE, coacd_threshold, convex_parts, hull_standoff

object_body_module = importlib.import_module("isf.simulation.object_body")

LENGTH, DEPTH, HEIGHT = 0.1, 0.05, 0.04
GROOVE_LOW, GROOVE_HIGH, GROOVE_FLOOR = 0.045, 0.055, 0.037


def _grooved_block() -> trimesh.Trimesh:
    """The block [0, 0.1] x [0, 0.05] x [0, 0.04] m less the groove
    [0.045, 0.055] x [0, 0.05] x [0.037, 0.04]: its x-z profile extruded along y."""
    profile = np.array([[0, 0], [GROOVE_LOW, 0], [GROOVE_HIGH, 0], [LENGTH, 0], [LENGTH, HEIGHT],
                        [GROOVE_HIGH, HEIGHT], [GROOVE_HIGH, GROOVE_FLOOR],
                        [GROOVE_LOW, GROOVE_FLOOR], [GROOVE_LOW, HEIGHT], [0, HEIGHT]])
    triangles = np.array([[0, 1, 7], [0, 7, 8], [0, 8, 9], [1, 2, 6], [1, 6, 7],
                          [2, 3, 4], [2, 4, 5], [2, 5, 6]])
    prism = trimesh.creation.extrude_triangulation(profile, triangles, DEPTH)
    # the profile's plane (x, y) is the block's x-z plane; the extrusion (z) is its y
    prism.apply_transform(np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]]))
    prism.apply_translation([0.0, DEPTH, 0.0])
    return prism


def _outside_distance(points: np.ndarray) -> np.ndarray:
    """Distance of each point from the grooved block, 0 inside it (closed form)."""
    outside_box = np.linalg.norm(np.maximum(0.0, np.maximum(-points, points - [LENGTH, DEPTH, HEIGHT])),
                                 axis=1)
    x, z = points[:, 0], points[:, 2]
    in_groove = (x > GROOVE_LOW) & (x < GROOVE_HIGH) & (z > GROOVE_FLOOR) & (outside_box == 0.0)
    groove = np.minimum(np.minimum(z - GROOVE_FLOOR, x - GROOVE_LOW), GROOVE_HIGH - x)
    return np.where(in_groove, groove, outside_box)


def _part_points(parts) -> np.ndarray:
    return np.concatenate([trimesh.sample.sample_surface(trimesh.Trimesh(v, f), 3000, seed=k)[0]
                           for k, (v, f) in enumerate(parts)])


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    """Decompositions of this module go to, and come from, a cache of its own."""
    monkeypatch.setenv("ISF_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(object_body_module, "_PARTS_CACHE", {})


def test_the_grooved_block_is_what_the_tests_assume():
    block = _grooved_block()
    assert block.is_watertight
    groove = (GROOVE_HIGH - GROOVE_LOW) * DEPTH * (HEIGHT - GROOVE_FLOOR)
    assert block.volume == pytest.approx(LENGTH * DEPTH * HEIGHT - groove, rel=1e-9)
    assert np.abs(_outside_distance(block.vertices)).max() == pytest.approx(0.0, abs=1e-12)
    # the hull fills the groove: its standoff is the groove's depth
    assert hull_standoff(block, block.convex_hull) == pytest.approx(HEIGHT - GROOVE_FLOOR, abs=1e-4)
    box = trimesh.creation.box(extents=(LENGTH, DEPTH, HEIGHT))
    assert hull_standoff(box, box.convex_hull) == pytest.approx(0.0, abs=1e-9)


def test_the_parts_stand_off_the_mesh_by_about_the_tolerance_not_the_grooves_depth():
    block = _grooved_block()
    parts = convex_parts(block.vertices, block.faces)
    assert len(parts) > 1  # not the hull, which stands 3 mm off the groove's floor
    standoff = _outside_distance(_part_points(parts))
    assert standoff.max() <= 1.5 * PART_TOLERANCE, standoff.max()
    # the parts still cover the block: their volumes add up to about its volume
    assert sum(trimesh.convex.convex_hull(v).volume for v, _ in parts) == pytest.approx(
        block.volume, rel=0.05)


def test_the_concavity_threshold_follows_the_tolerance_within_coacds_range():
    def threshold(side: float) -> float:
        return coacd_threshold(np.array([[0.0, 0.0, 0.0], [side, 0.5 * side, 0.1 * side]]))

    assert threshold(0.1) == pytest.approx(PART_TOLERANCE / 0.05)
    assert threshold(0.08) == pytest.approx(PART_TOLERANCE / 0.04)
    assert threshold(1.0) == 0.02  # no finer: CoACD's time grows steeply below
    assert threshold(0.01) == 0.05  # its default, for small parts such as fingertips


def test_a_decomposition_is_made_once_and_read_back_from_the_disk_cache(monkeypatch, tmp_path):
    block = _grooved_block()
    made = convex_parts(block.vertices, block.faces)
    assert len(list((tmp_path / "convex-parts").glob("*.npz"))) == 1

    def no_coacd(*args, **kwargs):
        raise AssertionError("decomposed again")

    monkeypatch.setattr(object_body_module, "_PARTS_CACHE", {})  # a new process
    monkeypatch.setattr(object_body_module, "_coacd_in_child", no_coacd)
    again = convex_parts(block.vertices, block.faces)
    assert len(again) == len(made)
    for (v1, f1), (v2, f2) in zip(made, again):
        np.testing.assert_array_equal(v1, v2)
        np.testing.assert_array_equal(f1, f2)


def test_a_damaged_cache_file_is_decomposed_again(monkeypatch, tmp_path):
    block = _grooved_block()
    made = convex_parts(block.vertices, block.faces)
    (stored,) = (tmp_path / "convex-parts").glob("*.npz")
    stored.write_bytes(b"not a decomposition")
    monkeypatch.setattr(object_body_module, "_PARTS_CACHE", {})
    again = convex_parts(block.vertices, block.faces)
    assert len(again) == len(made)
    with np.load(stored) as rewritten:
        assert len(rewritten.files) == 2 * len(made)
