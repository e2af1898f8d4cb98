"""The plan file's robot-ready fields: the TCP pose, the pre-grasp, every joint by URDF name and
the provenance, checked against independent computations (ElementTree, scipy, yourdfpy,
hashlib), the schema, and ``isf plan --out -`` / the user's umask end to end."""

import hashlib
import json
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import jsonschema
import numpy as np
import pytest
import trimesh
import yourdfpy
from scipy.spatial.transform import Rotation

import isf
from isf.gripper.bundled import bundled_grippers
from isf.planning.plan_json import SCHEMA_PATH, Provenance, plan_to_dict, quaternion_xyzw

ISF = "{urn:isf:gripper:1}"
MULTIPLIER, OFFSET = 0.5, 0.002  # the mimic follower of the test gripper


@pytest.fixture(scope="module")
def schema():
    return json.loads(SCHEMA_PATH.read_text())


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("robot")


@pytest.fixture(scope="module")
def urdf(folder):
    """flat-parallel with a TCP turned about x and a mimic follower at half speed plus 2 mm."""
    text = bundled_grippers()["flat-parallel"].read_text()
    text = text.replace('tcp_origin="0 0 0.08"', 'tcp_origin="0.001 0 0.08 0.3 0 0"')
    text = text.replace('<mimic joint="left_finger_joint" multiplier="1" offset="0"/>',
                        f'<mimic joint="left_finger_joint" multiplier="{MULTIPLIER}" '
                        f'offset="{OFFSET}"/>')
    assert text.count("0.3 0 0") == 1 and text.count(f'offset="{OFFSET}"') == 1
    path = folder / "jaw.urdf"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def object_file(folder):
    path = folder / "rod.stl"
    trimesh.creation.cylinder(radius=0.012, height=0.06, sections=48).export(path)
    return path


@pytest.fixture(scope="module")
def plan_dict(urdf, object_file, schema):
    gripper = isf.load_gripper(urdf)
    result = isf.plan(gripper, isf.load_object(object_file), samples=8, seed=0)
    data = plan_to_dict(result, pregrasp_distance=0.07,
                        provenance=Provenance(object_file, parameters={"note": "test"}))
    jsonschema.validate(data, schema)
    return data


def declared_T_root_tcp(urdf) -> np.ndarray:
    """The TCP read from the file with ElementTree (palm is the root link) and scipy's
    fixed-axis roll-pitch-yaw."""
    tag = ET.parse(urdf).getroot().find(f"{ISF}gripper")
    assert tag.get("tcp_link") == "palm"
    values = [float(v) for v in tag.get("tcp_origin").split()]
    T = np.eye(4)
    T[:3, 3] = values[:3]
    T[:3, :3] = Rotation.from_euler("xyz", values[3:]).as_matrix()
    return T


def test_tcp_pose_is_the_grasp_pose_times_the_declared_tcp(plan_dict, urdf):
    T_root_tcp = declared_T_root_tcp(urdf)
    assert plan_dict["tcp"]["declared"] and plan_dict["tcp"]["link"] == "palm"
    np.testing.assert_allclose(plan_dict["tcp"]["T_gripper_tcp"], T_root_tcp, atol=1e-12)
    assert plan_dict["tcp"]["quaternion_order"] == "xyzw"
    for g in plan_dict["grasps"]:
        T = np.array(g["T_object_gripper"]) @ T_root_tcp
        np.testing.assert_allclose(g["tcp"]["matrix"], T, atol=1e-12)
        np.testing.assert_allclose(g["tcp"]["position"], T[:3, 3], atol=1e-12)
        q = Rotation.from_matrix(T[:3, :3]).as_quat()  # scipy: x, y, z, w
        q = q if q[3] >= 0 else -q
        np.testing.assert_allclose(g["tcp"]["quaternion_xyzw"], q, atol=1e-9)


def test_pregrasp_backs_off_exactly_the_distance_along_the_approach_with_fingers_open(plan_dict):
    for g in plan_dict["grasps"]:
        R_object_gripper = np.array(g["T_object_gripper"])[:3, :3]
        approach = R_object_gripper @ [0.0, 0.0, 1.0]  # the tag's approach="0 0 1", palm = root
        moved = np.subtract(g["pregrasp"]["tcp"]["position"], g["tcp"]["position"])
        np.testing.assert_allclose(moved, -0.07 * approach, atol=1e-12)
        assert np.linalg.norm(moved) == pytest.approx(0.07, abs=1e-12)
        np.testing.assert_allclose(g["pregrasp"]["tcp"]["quaternion_xyzw"],
                                   g["tcp"]["quaternion_xyzw"], atol=1e-12)
        np.testing.assert_allclose(np.array(g["pregrasp"]["T_object_gripper"])[:3, 3],
                                   np.array(g["T_object_gripper"])[:3, 3] - 0.07 * approach,
                                   atol=1e-12)
        # opened: the leader at its upper limit (0.04 m), the follower as its mimic says
        assert g["pregrasp"]["joint_state"] == pytest.approx(
            {"left_finger_joint": 0.04, "right_finger_joint": MULTIPLIER * 0.04 + OFFSET})


def test_joint_state_has_the_mimic_followers_as_yourdfpy_moves_them(plan_dict, urdf):
    robot = yourdfpy.URDF.load(str(urdf), build_scene_graph=True, load_meshes=False)
    assert robot.actuated_joint_names == ["left_finger_joint"]
    for g in plan_dict["grasps"]:
        assert set(g["joint_state"]) == {"left_finger_joint", "right_finger_joint"}
        assert g["joint_state"]["left_finger_joint"] == g["joints"]["left_finger_joint"]
        robot.update_cfg({"left_finger_joint": g["joints"]["left_finger_joint"]})
        # the follower slides its link along its axis 0 -1 0 by its value
        follower = robot.get_transform("right_finger", "palm")[:3, 3] @ [0.0, -1.0, 0.0]
        assert g["joint_state"]["right_finger_joint"] == pytest.approx(follower, abs=1e-12)


def test_provenance_hashes_the_files(plan_dict, urdf, object_file):
    p = plan_dict["provenance"]
    assert p["isf_version"] == isf.__version__ and plan_dict["schema_version"] == 2
    assert p["gripper_file"] == str(urdf.resolve()) and p["object_file"] == str(object_file)
    assert p["gripper_sha256"] == hashlib.sha256(urdf.read_bytes()).hexdigest()
    assert p["object_sha256"] == hashlib.sha256(object_file.read_bytes()).hexdigest()
    assert (p["units"], p["scale"], p["sampler"], p["seed"]) == ("m", 1.0, "regret", 0)
    assert p["parameters"]["note"] == "test" and p["parameters"]["samples"] == 8
    assert p["parameters"]["pregrasp_distance"] == 0.07


def test_quaternion_against_scipy_including_half_turns():
    rng = np.random.default_rng(0)
    rotations = [Rotation.random(random_state=rng) for _ in range(200)]
    rotations += [Rotation.from_rotvec(math.pi * np.eye(3)[k]) for k in range(3)]
    rotations += [Rotation.from_rotvec(math.pi * np.array([1.0, 1.0, 0.0]) / math.sqrt(2))]
    for r in rotations:
        q = r.as_quat()
        ours = np.array(quaternion_xyzw(r.as_matrix()))
        assert np.linalg.norm(ours) == pytest.approx(1.0) and ours[3] >= 0
        assert min(np.abs(ours - q).max(), np.abs(ours + q).max()) < 1e-9


def test_default_tcp_is_the_centre_of_the_pads_without_a_tag(folder):
    text = bundled_grippers()["flat-parallel"].read_text()
    text = text.replace(' tcp_link="palm" tcp_origin="0 0 0.08"', "")
    path = folder / "untagged.urdf"
    path.write_text(text)
    gripper = isf.load_gripper(path)
    assert gripper.tcp_link is None
    # the 2 x 2 cm pads face each other at x = 0, z = 0.08 (docs/bundled-grippers.md)
    np.testing.assert_allclose(gripper.T_root_tcp[:3, 3], [0.0, 0.0, 0.08], atol=5e-4)
    np.testing.assert_array_equal(gripper.T_root_tcp[:3, :3], np.eye(3))


def test_a_tcp_on_a_finger_is_refused(folder):
    text = bundled_grippers()["flat-parallel"].read_text().replace('tcp_link="palm"',
                                                                  'tcp_link="left_finger"')
    path = folder / "finger_tcp.urdf"
    path.write_text(text)
    with pytest.raises(isf.GripperDescriptionError, match="moves with joint 'left_finger_joint'"):
        isf.load_gripper(path)


def run(*args, umask=None):
    return subprocess.run([sys.executable, "-m", "isf", *args], capture_output=True, text=True,
                          timeout=300, preexec_fn=None if umask is None else lambda: os.umask(umask))


def test_out_dash_prints_valid_json_and_files_get_the_umask(schema, tmp_path, object_file):
    proc = run("plan", "-g", "paper-parallel", "-o", str(object_file), "-n", "4", "--top", "3",
               "--out", "-", "--pregrasp-distance", "0.05")
    assert proc.returncode in (0, 1), proc.stderr
    data = json.loads(proc.stdout)
    jsonschema.validate(data, schema)
    assert len(data["grasps"]) == 3 and data["tcp"]["pregrasp_distance"] == 0.05
    assert "wrote 3 grasps to stdout" in proc.stderr
    assert data["provenance"]["object_sha256"] == \
        hashlib.sha256(object_file.read_bytes()).hexdigest()
    out = tmp_path / "grasps.json"
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2", "-q",
               "--out", str(out), umask=0o027)
    assert proc.returncode in (0, 1), proc.stderr
    assert out.stat().st_mode & 0o777 == 0o640
    jsonschema.validate(json.loads(out.read_text()), schema)


@pytest.mark.parametrize("attrs, problem", [
    ('tcp_link="palm" tcp_origin="0 0 0.1 0"', "must be 'x y z' (metres) or 'x y z roll pitch yaw'"),
    ('tcp_origin="0 0 0.1"', "tcp_origin needs tcp_link"),
    ('tcp_link="no_such_link"', "names a link that does not exist"),
])
def test_tcp_tag_mistakes_are_reported(folder, attrs, problem):
    text = bundled_grippers()["flat-parallel"].read_text()
    text = text.replace('tcp_link="palm" tcp_origin="0 0 0.08"', attrs)
    path = folder / "mistake.urdf"
    path.write_text(text)
    report = isf.inspect_gripper(path)
    assert any(problem in p for p in report.problems), report.problems


def test_suggested_tcp_lies_between_the_fingertips(tmp_path):
    """On the stock Franka hand (a vendor file): the tagged copy's TCP is on the hand's axis,
    between the finger links' origins (yourdfpy's poses) and their tips, 5.4 cm further."""
    from isf import assets
    from isf.registration import suggest_contacts, suggest_tcp, tag_urdf

    stock = assets.vendor_gripper("franka-hand")
    package_dirs = {"meshes": stock.parent / "meshes"}
    tcp = suggest_tcp(stock, package_dirs=package_dirs)
    contacts = suggest_contacts(stock, package_dirs=package_dirs)
    preview = tag_urdf(stock, tmp_path / "hand.urdf", contacts, package_dirs=package_dirs,
                       tcp=tcp)
    assert preview.ok, preview.report.problems
    gripper = isf.load_gripper(tmp_path / "hand.urdf")
    assert gripper.tcp_link == tcp.link == "hand"
    robot = yourdfpy.URDF.load(str(stock), build_scene_graph=True, load_meshes=False)
    p = gripper.T_root_tcp[:3, 3]
    assert np.hypot(p[0], p[1]) < 1e-3  # the hand is symmetric about its z axis
    base = robot.get_transform("left_finger", "hand")[2, 3]
    assert base < p[2] < base + 0.054


def test_inspect_shows_the_declared_tcp(urdf):
    from isf.gripper.loading import format_report

    report = isf.inspect_gripper(urdf)
    assert report.ok and report.tcp_link == "palm"
    np.testing.assert_allclose(report.T_link_tcp, declared_T_root_tcp(urdf), atol=1e-12)
    assert "tcp       0.001 0 0.08 m in palm" in format_report(report)
