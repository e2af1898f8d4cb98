"""``isf show`` without a browser: the page is self-contained, carries what the viewer draws,
and its numbers agree with a second computation; the plan file's ``convergence`` record."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import jsonschema
import numpy as np
import pytest
from scipy.spatial import cKDTree

import isf
from isf.planning.plan_json import SCHEMA_PATH, write_plan_json
from isf.viewer import GripperMeshes, PlanSources, load_sources, open_plan, report_data


def _isf(*args):
    return subprocess.run([sys.executable, "-m", "isf", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def plan_file(tmp_path_factory):
    """A small plan of the paper's gripper on isf's cylinder, written as ``isf plan`` writes it."""
    result = isf.plan("paper-parallel", isf.open_object("shape:cylinder"), samples=8, seed=1)
    return write_plan_json(result, tmp_path_factory.mktemp("plan") / "grasps.json"), result


def _page_data(html: str) -> dict:
    match = re.search(r'<script type="application/json" id="isf-data">(.*?)</script>', html, re.S)
    return json.loads(match.group(1))


def test_convergence_record_is_the_fit_history_and_follows_the_schema(plan_file):
    path, result = plan_file
    data = json.loads(path.read_text())
    jsonschema.validate(data, json.loads(SCHEMA_PATH.read_text()))
    for record, grasp in zip(data["grasps"], result.grasps):
        c, history = record["convergence"], grasp.fit.history
        assert len(c["level"]) == len(history) == record["iterations"] + 1  # the start, then each
        assert c["level"] == [r.level for r in history]
        assert c["ipfo_iterations"] == [len(r.ipfo_errors) for r in history]
        np.testing.assert_allclose(c["mean_distance"], [r.mean_distance for r in history], rtol=1e-4)
        np.testing.assert_allclose(c["joints"]["left_finger_joint"], [r.q[0] for r in history],
                                   rtol=1e-4)


def test_isf_show_writes_a_self_contained_page(plan_file, tmp_path):
    path, result = plan_file
    out = tmp_path / "report.html"
    proc = _isf("show", path, "--out", out, "--top", 5)
    assert proc.returncode == 0, proc.stderr
    html = out.read_text()
    from plotly.offline import get_plotlyjs

    bundle = get_plotlyjs()  # plotly.js as the plotly package ships it, inlined once
    assert html.count(bundle) == 1
    own = html.replace(bundle, "")
    # nothing fetched: no external src/href, no url(...), no protocol-relative address; the
    # bundle's own strings are checked in a browser (tests/test_viewer_browser.py)
    assert not re.search(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//""", own, re.I)
    assert not re.search(r"""url\(\s*["']?(?:https?:)?//""", own, re.I)
    assert "<script src" not in own and "<link" not in own
    assert "default-src 'none'" in own  # the page forbids itself any request
    data = _page_data(html)
    assert [g["rank"] for g in data["grasps"]] == [1, 2, 3, 4, 5]
    assert data["object"]["kind"] == "mesh" and data["table"] is None and data["unseen"] is None
    written = json.loads(path.read_text())["grasps"]
    for shown, record in zip(data["grasps"], written):
        assert shown["convergence"] == record["convergence"]
        assert shown["collision_free"] == record["collision_free"]


def _decode(text, dtype):
    import base64

    return np.frombuffer(base64.b64decode(text), dtype=np.dtype(dtype).newbyteorder("<"))


def test_page_poses_and_contact_distances_agree_with_a_second_computation(plan_file):
    path, result = plan_file
    plan = open_plan(path)
    sources = load_sources(plan)
    gripper, surface = sources.gripper, sources.surface
    meshes = GripperMeshes(gripper.urdf_path)
    data = report_data(plan, sources, meshes)
    tree = cKDTree(surface.points)
    local = _decode(data["contacts"]["points"], np.float32).reshape(-1, 3)
    for shown, grasp in zip(data["grasps"], result.grasps):
        # contact points: the fit's own contact points at the grasp (isf's kinematics), against
        # the page's link-frame points placed by its 3x4 poses, as report.js places them
        links = _decode(data["contacts"]["link"], np.int32)
        T = np.asarray(shown["T_links"]).reshape(-1, 3, 4)
        placed = np.einsum("pij,pj->pi", T[links, :, :3], local) + T[links, :, 3]
        expected, _ = gripper.contact_points(grasp.q)
        expected = expected @ grasp.T_object_gripper[:3, :3].T + grasp.T_object_gripper[:3, 3]
        np.testing.assert_allclose(np.sort(placed, axis=0), np.sort(expected, axis=0), atol=1e-6)
        # their distances: a k-d tree of scipy, unsigned
        distance = _decode(shown["distance"], np.float32)
        np.testing.assert_allclose(np.abs(distance), tree.query(placed)[0], atol=1e-6)
    # mesh parts: the first grasp's palm at T_object_gripper (the palm is the root link)
    names = [p["name"] for p in data["parts"]]
    palm = names.index("palm_body")
    T_palm = np.asarray(data["grasps"][0]["T_parts"]).reshape(-1, 3, 4)[palm]
    np.testing.assert_allclose(T_palm[:, :3], result.grasps[0].T_object_gripper[:3, :3], atol=1e-6)


def test_a_scene_plan_shows_its_table_and_unseen_space(tmp_path):
    pytest.importorskip("open3d")
    from _depth_camera import box_on_table, look_at, render_depth, table_mesh

    T = look_at((0.35, -0.25, 0.45), (0.0, 0.0, 0.05))
    depth, intrinsics = render_depth([table_mesh(), box_on_table((0.05, 0.05, 0.08))], T)
    np.save(tmp_path / "depth.npy", depth)
    np.savetxt(tmp_path / "pose.txt", T)
    plan = tmp_path / "scene.json"
    k = ",".join(str(intrinsics[n]) for n in ("fx", "fy", "cx", "cy"))
    proc = _isf("plan", "-g", "paper-parallel", "--scene", tmp_path / "depth.npy", "--intrinsics", k,
                "--camera-pose", tmp_path / "pose.txt", "--table", "auto", "-n", 4, "-q",
                "--out", plan)
    assert proc.returncode in (0, 1), proc.stderr
    out = tmp_path / "scene.html"
    proc = _isf("show", plan, "--out", out, "--object", tmp_path / "depth.npy", "--intrinsics", k)
    assert proc.returncode == 0, proc.stderr
    data = _page_data(out.read_text())
    assert data["object"]["kind"] == "cloud" and data["table"] is not None
    assert data["unseen"]["max"] > 0.0  # the box hides space behind it
    written = json.loads(plan.read_text())
    table = written["scene"]["table"]
    corners = _decode(data["table"]["vertices"], np.float32).reshape(-1, 3)
    np.testing.assert_allclose(corners @ np.asarray(table["normal"]), table["offset"], atol=1e-5)


@pytest.mark.parametrize("args, message", [
    (["show", "missing.json"], "is not a file"),
    (["show", "{plan}", "--top", "0"], "positive number"),
    (["export", "{plan}", "--rank", "99", "--out", "{tmp}/g.glb"], "no grasp of rank 99"),
    (["export", "{plan}", "--out", "{tmp}/g.stl"], "name a .glb"),
    (["show", "{plan}", "--gripper", "no-such-gripper"], "--gripper"),
])
def test_mistakes_exit_2_in_one_line(plan_file, tmp_path, args, message):
    path, _ = plan_file
    proc = _isf(*(a.format(plan=path, tmp=tmp_path) for a in args))
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_a_file_that_is_not_a_plan_is_refused(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"grippers": []}')
    proc = _isf("show", bad)
    assert proc.returncode == 2 and "not an isf grasp file" in proc.stderr


def test_sources_given_by_the_caller_win(plan_file):
    path, _ = plan_file
    plan = open_plan(path)
    from isf.viewer import SourceOptions

    sources = load_sources(plan, SourceOptions(gripper="flat-parallel"))
    assert isinstance(sources, PlanSources) and sources.gripper.name == "flat-parallel"


def test_the_list_carries_each_grasps_quality_and_physics_outcome(plan_file, tmp_path):
    path, _ = plan_file
    data = json.loads(path.read_text())
    valid = [g for g in data["grasps"] if g["quality"] is not None]
    assert valid, "the plan has no valid grasp to check"
    valid[0]["validation"] = {"outcome": "slipped", "held_directions": 4, "penetration": 0.0,
                              "closing_displacement": 0.001, "directions": {}}
    edited = tmp_path / "validated.json"
    edited.write_text(json.dumps(data))
    plan = open_plan(edited)
    sources = load_sources(plan)
    page = report_data(plan, sources, GripperMeshes(sources.gripper.urdf_path))
    rows = {row["rank"]: row for row in page["grasps"]}
    assert rows[valid[0]["rank"]]["physics"] == "slipped 4/6"
    assert rows[valid[0]["rank"]]["epsilon"] == valid[0]["quality"]["epsilon"]
    assert rows[valid[0]["rank"]]["squeeze_imbalance"] == valid[0]["quality"]["squeeze_imbalance"]
    assert all(rows[g["rank"]]["closing_obstructed_by"] == g["closing_obstructed_by"] for g in valid)
    others = [g["rank"] for g in data["grasps"] if "validation" not in g]
    assert all(rows[rank]["physics"] is None for rank in others)
