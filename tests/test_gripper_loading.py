"""Loading tagged URDFs: validation messages, mesh paths, mimic joints, surface sampling."""

from __future__ import annotations

import os

import numpy as np
import pytest
import trimesh

from isf.exceptions import GripperDescriptionError
from isf.gripper.bundled import bundled_grippers
from isf.gripper.loading import format_report, inspect_gripper, load_gripper
from isf.gripper.mesh_paths import MeshNotFoundError, mesh_path_candidates, resolve_mesh_path
from isf.gripper.urdf_tags import rpy_matrix

NS = 'xmlns:isf="urn:isf:gripper:1"'

# A parallel gripper: palm box, two box fingers on a prismatic joint and its mimic.
# Finger boxes are 1 x 1 x 4 cm, centred 2 cm above their link origin.
BASE = """<?xml version="1.0"?>
<robot name="two_pads" {ns}>
  <link name="palm">
    <collision name="palm_box"><geometry><box size="0.1 0.02 0.02"/></geometry></collision>
  </link>
  <link name="left_finger">
    <collision name="left_body"><origin xyz="0 0 0.02"/>
      <geometry><box size="0.01 0.01 0.04"/></geometry></collision>
  </link>
  <link name="right_finger">
    <collision name="right_body"><origin xyz="0 0 0.02"/>
      <geometry><box size="0.01 0.01 0.04"/></geometry></collision>
  </link>
  <joint name="left_joint" type="prismatic"><parent link="palm"/><child link="left_finger"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="prismatic"><parent link="palm"/><child link="right_finger"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/>
    <mimic joint="left_joint" multiplier="1" offset="0"/></joint>
  <isf:gripper palm_link="palm" approach="0 0 2"/>
  <isf:contact name="left" link="left_finger" normal="0 -1 0" points="64"/>
  <isf:contact name="right" link="right_finger" normal="0 1 0" points="64"/>
  <isf:initial joint="left_joint" value="0.03"/>
</robot>
"""


def write(tmp_path, text, name="g.urdf"):
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text.replace("{ns}", NS))
    return path


def write_box_stl(path, extents, transform=None):
    """Write a box mesh (STL) and return it as trimesh (vertices as written)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = trimesh.creation.box(extents=extents, transform=transform)
    mesh.export(path)
    return mesh


# ------------------------------------------------------------------ success
def test_base_gripper_loads_with_tags_applied(tmp_path):
    write(tmp_path, BASE)
    gripper = load_gripper(tmp_path)  # a folder holding one URDF
    assert gripper.name == "g"
    assert gripper.joint_names == ("left_joint",)
    np.testing.assert_allclose(gripper.q_initial, [0.03])
    assert gripper.palm_link == "palm"
    np.testing.assert_allclose(gripper.approach, [0, 0, 1])
    assert [s.name for s in gripper.surfaces] == ["left", "right"]
    assert {g.name for g in gripper.geometries} == {"palm_box", "left_body", "right_body"}


def test_box_face_area_points_and_normals_are_analytic(tmp_path):
    gripper = load_gripper(write(tmp_path, BASE))
    left = gripper.surfaces[0]
    # the -y face of a 1 x 1 x 4 cm box whose centre is 2 cm above the link origin
    assert left.area == pytest.approx(0.01 * 0.04, rel=1e-12)
    assert left.points.shape == (64, 3)
    np.testing.assert_allclose(left.points[:, 1], -0.005, atol=1e-12)
    assert np.all(np.abs(left.points[:, 0]) <= 0.005 + 1e-12)
    assert np.all((left.points[:, 2] >= -1e-12) & (left.points[:, 2] <= 0.04 + 1e-12))
    np.testing.assert_allclose(left.normals, np.tile([0, -1, 0], (64, 1)), atol=1e-12)


def test_sampling_is_deterministic_and_farthest_point_ordered(tmp_path):
    path = write(tmp_path, BASE)
    a, b = load_gripper(path).surfaces[0], load_gripper(path).surfaces[0]
    np.testing.assert_array_equal(a.points, b.points)
    pts = a.points
    # first point: nearest the face centroid (0, -0.005, 0.02)
    centre = np.array([0.0, -0.005, 0.02])
    assert np.argmin(np.linalg.norm(pts - centre, axis=1)) == 0
    # each next point is the farthest from all earlier ones (brute force check)
    for i in range(1, len(pts)):
        d_prev = np.min(np.linalg.norm(pts[:i, None] - pts[None, i:], axis=2), axis=0)
        assert d_prev[0] == pytest.approx(d_prev.max())


def test_points_lie_on_selected_faces_of_a_scaled_transformed_mesh(tmp_path):
    # A convex mesh in millimetres, placed by <origin> with a rotation: every sampled
    # point must lie on the hull (max plane distance 0) with the normal of its face.
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=10.0)
    sphere.vertices = sphere.vertices.astype(np.float32).astype(float)  # STL stores float32
    (tmp_path / "meshes").mkdir()
    sphere.export(tmp_path / "meshes" / "ball.stl")
    xyz, rpy = np.array([0.01, -0.02, 0.03]), np.array([0.3, -0.4, 1.1])
    text = BASE.replace(
        '<collision name="left_body">',
        f'<collision name="ball"><origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/>'
        '<geometry><mesh filename="meshes/ball.stl" scale="0.001 0.001 0.001"/></geometry></collision>'
        '<collision name="left_body">',
    ).replace(
        '<isf:contact name="left" link="left_finger" normal="0 -1 0" points="64"/>',
        '<isf:contact name="left" link="left_finger" geometry="ball" normal="0 0 1" max_angle="0.8" points="200"/>',
    )
    surface = load_gripper(write(tmp_path, text)).surfaces[0]
    R = rpy_matrix(rpy)
    verts = 0.001 * sphere.vertices @ R.T + xyz
    tri = verts[sphere.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    offset = np.einsum("fi,fi->f", n, tri[:, 0])
    signed = surface.points @ n.T - offset  # (N, F): <= 0 inside the convex hull
    assert np.abs(signed.max(axis=1)).max() < 1e-12
    np.testing.assert_allclose(surface.normals, n[signed.argmax(axis=1)], atol=1e-9)
    assert np.all(surface.normals @ [0, 0, 1] >= np.cos(0.8) - 1e-12)
    kept = n @ [0, 0, 1] >= np.cos(0.8)
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert surface.area == pytest.approx(areas[kept].sum(), rel=1e-9)


def test_box_selection_and_visual_source(tmp_path):
    # source="visual" reads the 2 x 1 x 4 cm visual box, not the collision box; the
    # selection box (no normal cone) keeps faces whose centroid has y >= 4 mm: only the
    # +y face (triangle centroids of the x and z faces have |y| = 1.7 mm).
    text = BASE.replace(
        '<collision name="right_body">',
        '<visual name="right_shape"><origin xyz="0 0 0.02"/>'
        '<geometry><box size="0.02 0.01 0.04"/></geometry></visual><collision name="right_body">',
    ).replace(
        '<isf:contact name="right" link="right_finger" normal="0 1 0" points="64"/>',
        '<isf:contact name="right" link="right_finger" source="visual" box_min="-1 0.004 -1" points="64"/>',
    )
    gripper = load_gripper(write(tmp_path, text))
    right = gripper.surfaces[1]
    assert right.area == pytest.approx(0.02 * 0.04, rel=1e-12)
    # the link has a collision, so its visual is not part of the collision geometry
    assert "right_shape" not in {g.name for g in gripper.geometries}
    np.testing.assert_allclose(right.points[:, 1], 0.005, atol=1e-12)
    np.testing.assert_allclose(right.normals, np.tile([0, 1, 0], (64, 1)), atol=1e-12)


# ------------------------------------------------------------------- problems
PROBLEM_CASES = {
    "no_contact": (
        lambda t: t.replace(
            '<isf:contact name="left" link="left_finger" normal="0 -1 0" points="64"/>', ""
        ).replace('<isf:contact name="right" link="right_finger" normal="0 1 0" points="64"/>', ""),
        "no <isf:contact> tag",
    ),
    "missing_link": (
        lambda t: t.replace('link="left_finger" normal', 'link="lft_finger" normal'),
        "contact 'left' names link 'lft_finger', which does not exist",
    ),
    "missing_geometry": (
        lambda t: t.replace(
            'link="left_finger" normal', 'link="left_finger" geometry="pad" normal'
        ),
        "link 'left_finger' has no <collision> named 'pad'; its collision elements are 'left_body'",
    ),
    "missing_mesh": (
        lambda t: t.replace(
            '<box size="0.01 0.01 0.04"/>', '<mesh filename="meshes/nope.stl"/>', 1
        ),
        "mesh 'meshes/nope.stl' not found (tried",
    ),
    "empty_selection": (
        lambda t: t.replace(
            'normal="0 -1 0" points="64"', 'normal="0 -1 0" box_min="0.5 0.5 0.5" points="64"'
        ),
        "contact 'left': the selection keeps no face",
    ),
    "inward_normals": (
        lambda t: t.replace(
            'normal="0 -1 0" points="64"', 'normal="0 -1 0" flip="true" points="64"'
        ),
        "contact 'left': the normals of 'left_body' point into link 'left_finger'",
    ),
    "no_limits": (
        lambda t: t.replace(
            '<limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>', "</joint>", 1
        ),
        "actuated joint 'left_joint' lacks finite limits",
    ),
    "initial_outside": (
        lambda t: t.replace('value="0.03"', 'value="0.05"'),
        "<isf:initial joint='left_joint'> value=0.05 lies outside the joint limits [0.0, 0.04]",
    ),
    "initial_missing_joint": (
        lambda t: t.replace('<isf:initial joint="left_joint"', '<isf:initial joint="middle_joint"'),
        "<isf:initial joint='middle_joint'> names a joint that does not exist",
    ),
    "initial_mimic_joint": (
        lambda t: t.replace('<isf:initial joint="left_joint"', '<isf:initial joint="right_joint"'),
        "the joint mimics 'left_joint'; give the initial value of 'left_joint' instead",
    ),
    "continuous": (
        lambda t: t.replace(
            'name="left_joint" type="prismatic"', 'name="left_joint" type="continuous"'
        ),
        "joint 'left_joint' is continuous, which isf does not support",
    ),
    "undeclared_isf": (
        lambda t: t.replace("{ns}", ""),
        'the isf: prefix is not declared: add xmlns:isf="urn:isf:gripper:1"',
    ),
    "typo_attribute": (
        lambda t: t.replace('points="64"/>', 'pionts="64"/>', 1),
        "<isf:contact name='left'> has unknown attribute(s) pionts",
    ),
}


@pytest.mark.parametrize("case", sorted(PROBLEM_CASES))
def test_each_problem_is_reported(tmp_path, case):
    edit, message = PROBLEM_CASES[case]
    path = write(tmp_path, edit(BASE))
    with pytest.raises(GripperDescriptionError) as info:
        load_gripper(path)
    assert any(message in e for e in info.value.errors), info.value.errors
    assert info.value.source == str(path)
    report = inspect_gripper(path)  # never raises, same findings
    assert report.problems == info.value.errors
    assert not report.ok


def test_missing_mesh_lists_the_path_tried(tmp_path):
    path = write(tmp_path, PROBLEM_CASES["missing_mesh"][0](BASE))
    errors = inspect_gripper(path).problems
    assert any(str(tmp_path / "meshes" / "nope.stl") in e for e in errors)


def test_undeclared_isf_prefix_still_reads_the_tags(tmp_path):
    report = inspect_gripper(write(tmp_path, BASE.replace("{ns}", "")))
    assert len(report.problems) == 1
    assert [s.name for s in report.surfaces] == ["left", "right"]


def test_every_problem_is_listed_at_once(tmp_path):
    cases = ("missing_link", "initial_outside", "undeclared_isf")
    text = BASE.replace(
        'name="right_joint" type="prismatic"', 'name="right_joint" type="continuous"'
    )
    for case in cases:
        text = PROBLEM_CASES[case][0](text)
    with pytest.raises(GripperDescriptionError) as info:
        load_gripper(write(tmp_path, text))
    for case in cases:
        assert any(PROBLEM_CASES[case][1] in e for e in info.value.errors), case
    assert any("joint 'right_joint' is continuous" in e for e in info.value.errors)
    assert "4 problems" in str(info.value)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "is neither a URDF file nor a bundled gripper"),
        ("<robot name='x'><link name='a'>", "not valid XML"),
        ("<sdf version='1.6'><model name='m'/></sdf>", "not a URDF: the root element is <sdf>"),
    ],
)
def test_unreadable_sources(tmp_path, content, message):
    path = tmp_path / "bad.urdf"
    if content is not None:
        path.write_text(content)
    with pytest.raises(GripperDescriptionError) as info:
        load_gripper(path)
    assert len(info.value.errors) == 1 and message in info.value.errors[0]
    assert message in format_report(inspect_gripper(path))


def test_open_sheet_orientation_uses_the_link_centroid(tmp_path):
    # A single square sheet (open mesh) 1 cm in front of the finger body at -y.
    sheet = trimesh.Trimesh(
        vertices=[
            [-0.005, -0.01, 0.0],
            [0.005, -0.01, 0.0],
            [0.005, -0.01, 0.04],
            [-0.005, -0.01, 0.04],
        ],
        faces=[[0, 1, 2], [0, 2, 3]],  # counter-clockwise seen from -y: normal -y (outward)
        process=False,
    )
    np.testing.assert_allclose(sheet.face_normals, [[0, -1, 0]] * 2)
    sheet.export(tmp_path / "sheet.stl")
    text = BASE.replace(
        '<collision name="left_body">',
        '<collision name="sheet"><geometry><mesh filename="sheet.stl"/></geometry></collision>'
        '<collision name="left_body">',
    ).replace('link="left_finger" normal="0 -1 0"', 'link="left_finger" geometry="sheet"')
    good = inspect_gripper(write(tmp_path, text))
    assert good.ok, good.problems
    bad = inspect_gripper(
        write(tmp_path, text.replace('geometry="sheet"', 'geometry="sheet" flip="true"'), "b.urdf")
    )
    assert any("the normals of 'sheet' point into link 'left_finger'" in p for p in bad.problems)


def test_foreign_undeclared_prefix_is_tolerated(tmp_path):
    text = BASE.replace(
        "</robot>",
        '<drake:collision_filter_group name="g"><drake:member link="palm"/>'
        "</drake:collision_filter_group></robot>",
    )
    report = inspect_gripper(write(tmp_path, text))
    assert report.ok, report.problems


# ----------------------------------------------------------------- mesh paths
def test_mesh_path_resolution(tmp_path):
    urdf_dir = tmp_path / "ws" / "my_pkg" / "urdf"
    urdf_dir.mkdir(parents=True)
    rel = tmp_path / "ws" / "my_pkg" / "meshes" / "a.stl"
    rel.parent.mkdir()
    rel.write_text("x")
    assert resolve_mesh_path("../meshes/a.stl", urdf_dir) == rel
    assert resolve_mesh_path(str(rel), tmp_path) == rel
    assert resolve_mesh_path(f"file://{rel}", tmp_path) == rel
    # package:// via a parent folder named like the package
    assert resolve_mesh_path("package://my_pkg/meshes/a.stl", urdf_dir) == rel
    # package:// via a sibling folder of a parent (<parent>/pkg)
    other = tmp_path / "ws" / "other_pkg" / "b.stl"
    other.parent.mkdir()
    other.write_text("x")
    assert resolve_mesh_path("package://other_pkg/b.stl", urdf_dir) == other
    # the explicit map wins over the search
    mapped = tmp_path / "elsewhere" / "meshes" / "a.stl"
    mapped.parent.mkdir(parents=True)
    mapped.write_text("x")
    got = resolve_mesh_path(
        "package://my_pkg/meshes/a.stl", urdf_dir, {"my_pkg": tmp_path / "elsewhere"}
    )
    assert got == mapped
    # Franka style: package://meshes/... for a meshes folder beside the URDF
    franka = urdf_dir / "meshes" / "collision" / "finger.obj"
    franka.parent.mkdir(parents=True)
    franka.write_text("x")
    assert resolve_mesh_path("package://meshes/collision/finger.obj", urdf_dir) == franka
    # unknown package: fall back to the rest of the path relative to the URDF folder
    (urdf_dir / "c.stl").write_text("x")
    assert resolve_mesh_path("package://unknown_pkg/c.stl", urdf_dir) == urdf_dir / "c.stl"
    with pytest.raises(MeshNotFoundError) as info:
        resolve_mesh_path("package://nope/d.stl", urdf_dir, {"nope": tmp_path / "nope"})
    assert info.value.tried[0] == tmp_path / "nope" / "d.stl"
    assert info.value.tried == mesh_path_candidates(
        "package://nope/d.stl", urdf_dir, {"nope": tmp_path / "nope"}
    )


def test_package_mesh_with_scale_and_package_map(tmp_path):
    # Allegro-like layout: package://<pkg>/robots/<robot>/meshes/..., mesh in millimetres
    pkg = tmp_path / "share" / "example-pkg"
    write_box_stl(pkg / "robots" / "hand" / "meshes" / "pad.stl", [10.0, 20.0, 30.0])
    text = BASE.replace(
        '<box size="0.01 0.01 0.04"/>',
        '<mesh filename="package://example-pkg/robots/hand/meshes/pad.stl" scale="0.001 0.001 0.001"/>',
        1,
    )
    # the URDF sits inside the package: found by the parent-folder search
    inside = write(pkg / "robots" / "hand" / "urdf", text)
    surface = load_gripper(inside).surfaces[0]
    assert surface.area == pytest.approx(0.010 * 0.030)  # the -y face of 10 x 20 x 30 mm
    np.testing.assert_allclose(surface.points[:, 1], -0.010, atol=1e-12)
    # elsewhere: needs the package map
    outside = write(tmp_path / "elsewhere", text)
    assert not inspect_gripper(outside).ok
    gripper = load_gripper(outside, package_dirs={"example-pkg": str(pkg)})
    assert gripper.surfaces[0].area == pytest.approx(0.010 * 0.030)


def test_mirroring_scale_keeps_normals_outward(tmp_path):
    # a 10 mm cube centred at x = +15 mm, mirrored by scale -0.001 to x = -15 mm
    write_box_stl(
        tmp_path / "cube.stl",
        [10.0, 10.0, 10.0],
        trimesh.transformations.translation_matrix([15, 0, 0]),
    )
    text = BASE.replace(
        '<box size="0.01 0.01 0.04"/>', '<mesh filename="cube.stl" scale="-0.001 0.001 0.001"/>', 1
    ).replace('link="left_finger" normal="0 -1 0"', 'link="left_finger" normal="-1 0 0"')
    report = inspect_gripper(write(tmp_path, text))
    assert report.ok, report.problems
    surface = load_gripper(write(tmp_path, text)).surfaces[0]
    np.testing.assert_allclose(surface.points[:, 0], -0.020, atol=1e-9)
    assert surface.area == pytest.approx(1e-4, rel=1e-6)


def test_cylinder_cap_area_matches_its_polygon(tmp_path):
    text = BASE.replace(
        '<box size="0.01 0.01 0.04"/>', '<cylinder radius="0.008" length="0.03"/>', 1
    ).replace(
        'link="left_finger" normal="0 -1 0"', 'link="left_finger" normal="0 0 1" max_angle="0.1"'
    )
    surface = load_gripper(write(tmp_path, text)).surfaces[0]
    n = 48  # sections used for URDF cylinders
    assert surface.area == pytest.approx(0.5 * n * 0.008**2 * np.sin(2 * np.pi / n), rel=1e-9)
    np.testing.assert_allclose(surface.points[:, 2], 0.02 + 0.015, atol=1e-12)
    assert np.all(np.hypot(surface.points[:, 0], surface.points[:, 1]) <= 0.008 + 1e-12)


def test_robotiq_style_relative_paths_and_mixed_units(tmp_path):
    root = tmp_path / "robotiq"
    write_box_stl(root / "meshes" / "collision" / "finger.stl", [10.0, 10.0, 40.0])  # mm
    write_box_stl(root / "meshes" / "collision" / "palm.stl", [0.1, 0.02, 0.02])  # metres
    text = (
        BASE.replace(
            '<box size="0.1 0.02 0.02"/>', '<mesh filename="../meshes/collision/palm.stl"/>'
        )
        .replace(
            '<box size="0.01 0.01 0.04"/>',
            '<mesh filename="../meshes/collision/finger.stl" scale="0.001 0.001 0.001"/>',
        )
        .replace("{ns}", "")
        .replace("<robot ", f"<robot {NS} ")
    )
    gripper = load_gripper(write(root / "urdf", text))
    by_name = {g.name: g for g in gripper.geometries}
    np.testing.assert_allclose(np.ptp(by_name["palm_box"].vertices, axis=0), [0.1, 0.02, 0.02])
    np.testing.assert_allclose(np.ptp(by_name["left_body"].vertices, axis=0), [0.01, 0.01, 0.04])
    np.testing.assert_allclose(by_name["left_body"].vertices.mean(axis=0), [0, 0, 0.02], atol=1e-12)


# -------------------------------------------------------------------- mimic
MIMIC = """<robot name="mimic" {ns}>
  <link name="palm"><collision><geometry><box size="0.1 0.02 0.02"/></geometry></collision></link>
  <link name="left"><collision><geometry><box size="0.01 0.01 0.04"/></geometry></collision></link>
  <link name="right"><visual><geometry><box size="0.01 0.01 0.04"/></geometry></visual></link>
  <link name="tip"><collision><origin xyz="0 0 0.01"/><geometry><sphere radius="0.005"/></geometry></collision></link>
  <joint name="lead" type="prismatic"><parent link="palm"/><child link="left"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="follow" type="prismatic"><parent link="palm"/><child link="right"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="lead" multiplier="-1" offset="0.01"/></joint>
  <joint name="tip_joint" type="revolute"><parent link="left"/><child link="tip"/>
    <origin xyz="0 0 0.04"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="lead" multiplier="20" offset="0.1"/></joint>
  <isf:contact name="pad" link="left" normal="0 -1 0" points="16"/>
</robot>"""


def test_mimic_joints_follow_their_leader(tmp_path):
    gripper = load_gripper(write(tmp_path, MIMIC))
    assert gripper.n_joints == 1 and gripper.joint_names == ("lead",)
    np.testing.assert_allclose(gripper.q_initial, [0.02])  # middle of [0, 0.04]
    for q in (0.0, 0.013, 0.04):
        poses = gripper.link_poses(np.array([q]))
        np.testing.assert_allclose(poses["left"][:3, 3], [0, q, 0.05], atol=1e-12)
        np.testing.assert_allclose(poses["right"][:3, 3], [0, -q + 0.01, 0.05], atol=1e-12)
        angle = 20 * q + 0.1
        c, s = np.cos(angle), np.sin(angle)
        np.testing.assert_allclose(
            poses["tip"][:3, :3], [[1, 0, 0], [0, c, -s], [0, s, c]], atol=1e-12
        )
        np.testing.assert_allclose(poses["tip"][:3, 3], [0, q, 0.09], atol=1e-12)
        points, _ = gripper.contact_points(np.array([q]))
        np.testing.assert_allclose(points, gripper.surfaces[0].points + [0, q, 0.05], atol=1e-12)


def test_mimic_listed_before_its_leader_matches_the_natural_order(tmp_path):
    # Pinocchio visits sibling joints in name order and rejects 'follow' (mimic) before
    # 'lead'; the loader rebuilds with a leader-first order and restores the names.
    import pinocchio as pin

    text = MIMIC.replace("{ns}", NS)
    with pytest.raises(ValueError, match="mimic"):
        pin.buildModelFromXML(text, mimic=True)
    rebuilt = load_gripper(write(tmp_path, MIMIC))
    natural = load_gripper(write(tmp_path, MIMIC.replace('"follow"', '"z_follow"'), "n.urdf"))
    names = {rebuilt.model.names[i] for i in range(rebuilt.model.njoints)}
    assert names == {"universe", "lead", "follow", "tip_joint"}
    assert {f.name for f in rebuilt.model.frames} >= {"lead", "follow", "tip_joint", "left", "tip"}
    rng = np.random.default_rng(3)
    for q in rng.uniform(0.0, 0.04, size=(5, 1)):
        a, b = rebuilt.link_poses(q), natural.link_poses(q)
        for link in ("left", "right", "tip"):
            np.testing.assert_allclose(a[link], b[link], atol=1e-12)


def test_report_describes_joints_meshes_and_surfaces(tmp_path):
    report = inspect_gripper(write(tmp_path, MIMIC))
    assert report.ok and report.root_link == "palm" and report.palm_link == "palm"
    assert report.links == ("palm", "left", "right", "tip")
    follow = next(j for j in report.joints if j.name == "follow")
    assert (follow.mimic_leader, follow.mimic_multiplier, follow.mimic_offset) == (
        "lead",
        -1.0,
        0.01,
    )
    assert not follow.actuated and next(j for j in report.joints if j.name == "lead").actuated
    assert [(s.name, s.link, s.n_points) for s in report.surfaces] == [("pad", "left", 16)]
    assert report.surfaces[0].area == pytest.approx(0.01 * 0.04)
    text = format_report(report)
    for needle in ("lead", "-1 * lead + 0.01", "pad", "OK"):
        assert needle in text


def test_geometries_fall_back_to_visuals_and_default_names(tmp_path):
    gripper = load_gripper(write(tmp_path, MIMIC))
    names = {(g.link, g.name) for g in gripper.geometries}
    assert names == {("palm", "palm_0"), ("left", "left_0"), ("right", "right_0"), ("tip", "tip_0")}
    tip = next(g for g in gripper.geometries if g.link == "tip")
    # sphere of radius 5 mm centred 1 cm up the tip link (icosphere vertices lie on it)
    np.testing.assert_allclose(
        np.linalg.norm(tip.vertices - [0, 0, 0.01], axis=1), 0.005, atol=1e-12
    )


def test_missing_unused_visual_mesh_is_reported_but_not_a_problem(tmp_path):
    text = MIMIC.replace(
        '<link name="palm"><collision>',
        '<link name="palm"><visual><geometry><mesh filename="gone.dae"/></geometry></visual><collision>',
    )
    report = inspect_gripper(write(tmp_path, text))
    assert report.ok, report.problems
    (mesh,) = report.meshes
    assert not mesh.found and not mesh.used and mesh.tried == (tmp_path / "gone.dae",)
    assert "missing (unused): palm/palm_0: gone.dae" in format_report(report)


# ------------------------------------------------------------------ bundled
def test_bundled_grippers_load_quickly():
    bundled = bundled_grippers()
    assert list(bundled) == sorted(bundled)
    if not bundled:
        pytest.skip("no bundled grippers in this checkout (grippers/ folder is empty)")
    for name, path in bundled.items():
        assert path.name == f"{name}.urdf"
        report = inspect_gripper(name)
        assert report.ok, (name, report.problems)
        assert report.load_time < (1.0 if os.environ.get("CI") else 0.5), name
        assert load_gripper(name).name == name
