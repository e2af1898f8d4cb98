"""``isf export``: the gripper in the written scene is where isf's own kinematics (Pinocchio,
``Gripper.link_poses``) puts its link meshes; every format loads back with trimesh."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import isf
from isf.planning.plan_json import write_plan_json
from isf.viewer import GripperMeshes


def _isf(*args):
    return subprocess.run([sys.executable, "-m", "isf", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module", params=["paper-parallel", "three-finger"])
def plan(request, tmp_path_factory):
    """A plan file of a bundled gripper (paper-parallel: a mimic finger; three-finger: six
    revolute joints) on isf's cylinder (scaled for the hand), the plan, and the options that
    give ``isf export`` the object's scale."""
    scale = 3.0 if request.param == "three-finger" else 1.0
    result = isf.plan(request.param, isf.open_object("shape:cylinder", scale=scale), samples=4,
                      seed=3)
    path = write_plan_json(result, tmp_path_factory.mktemp("plan") / "grasps.json")
    return path, result, ("--scale", scale)


def _expected_links(gripper: isf.Gripper, grasp) -> dict[str, np.ndarray]:
    """Each geometry element's vertices in the object frame by isf's own loader and kinematics."""
    poses = gripper.link_poses(grasp.q)
    out = {}
    for g in gripper.geometries:
        T = grasp.T_object_gripper @ poses[g.link]
        out[g.name] = g.vertices @ T[:3, :3].T + T[:3, 3]
    return out


def test_glb_gripper_matches_pinocchio_forward_kinematics(plan, tmp_path):
    path, result, scale = plan
    rank = min(2, len(result.grasps))
    out = tmp_path / "grasp.glb"
    proc = _isf("export", path, "--rank", rank, "--out", out, *scale)
    assert proc.returncode == 0, proc.stderr
    scene = trimesh.load(out, force="scene")
    grasp = result.grasps[rank - 1]
    expected = _expected_links(isf.load_gripper(result.gripper), grasp)
    compared = 0
    for node in scene.graph.nodes_geometry:
        T, key = scene.graph[node]
        if node not in expected or len(scene.geometry[key].vertices) != len(expected[node]):
            continue  # a URDF <cylinder>: isf and yourdfpy cut it into different facets
        vertices = scene.geometry[key].vertices @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(vertices, expected[node], atol=1e-6, err_msg=node)
        compared += 1
    # every finger link was compared, including a mimic joint's (paper-parallel's right finger)
    fingers = {g.name for g in isf.load_gripper(result.gripper).geometries if g.link != "palm"}
    assert compared >= len(fingers) > 0
    obj = isf.open_object("shape:cylinder", scale=scale[1])
    T, key = scene.graph["object"]
    np.testing.assert_allclose(scene.geometry[key].vertices @ T[:3, :3].T + T[:3, 3],
                               obj.mesh_vertices, atol=1e-6)


@pytest.mark.parametrize("suffix", ["ply", "obj"])
def test_ply_and_obj_load_back_with_every_triangle(plan, tmp_path, suffix):
    path, result, scale = plan
    out = tmp_path / f"grasp.{suffix}"
    proc = _isf("export", path, "--out", out, *scale)
    assert proc.returncode == 0, proc.stderr
    loaded = trimesh.load(out, force="mesh", process=False)
    gripper = isf.load_gripper(result.gripper)
    expected = _expected_links(gripper, result.grasps[0])
    obj = isf.open_object("shape:cylinder", scale=scale[1])
    meshes = GripperMeshes(gripper.urdf_path)  # what was written: the round trip keeps it all
    assert len(loaded.faces) == len(obj.mesh_faces) + sum(len(p.faces) for p in meshes.parts)
    # the gripper's vertices lie where isf's kinematics puts them (elements tessellated alike:
    # a URDF <cylinder> is cut into different facets by isf and by yourdfpy)
    alike = {p.name for p in meshes.parts if p.name in expected and len(p.vertices) == len(expected[p.name])}
    assert len(alike) >= len(meshes.parts) - 1
    everything = np.concatenate([expected[name] for name in sorted(alike)])
    assert cKDTree(loaded.vertices).query(everything)[0].max() < 1e-5
