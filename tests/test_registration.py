"""Registration workflow on real vendor URDFs: suggest, tag a copy, validate, plan.

Independent references: the vendor files themselves (hash before/after, a line diff against
the copy, fingertip links and finger axes read off the files by hand), the loaded gripper's own
sampled contact points, trimesh distance queries on the YCB mesh, and the tutorial text.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import os
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

import isf
from isf.assets import AssetFetchError, YCBNotFoundError, benchmark_object, vendor_gripper
from isf.registration import (
    ContactSpec,
    RegistrationError,
    suggest_approach,
    suggest_contacts,
    tag_urdf,
)

ISF_XMLNS = ' xmlns:isf="urn:isf:gripper:1"'
TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial-register.md"
YCB_OBJECT = "ycb:GelatinBox"

# Fingertip links, read off the vendor files: the Franka's two fingers, the Robotiq's two
# pads (not the inner knuckles, leaves of the four-bar linkage), the Allegro's four tip
# links (sphere collisions) and the PR2's two tips.
FINGERTIPS = {
    "franka-hand": {"left_finger", "right_finger"},
    "robotiq-2f-85": {"left_inner_finger_pad", "right_inner_finger_pad"},
    "allegro-right": {"link_3.0_tip", "link_7.0_tip", "link_11.0_tip", "link_15.0_tip"},
    "pr2-gripper": {"left_tip", "right_tip"},
}
# Parallel jaws and the axis of the root frame they close along, read off the files: the
# Franka's fingers slide along y (joint axis 0 1 0); the Robotiq's pads sit at x = -+23 mm.
CLOSING_AXIS = {"franka-hand": (0.0, 1.0, 0.0), "robotiq-2f-85": (1.0, 0.0, 0.0)}
TIMINGS: dict[str, float] = {}


def sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def vendor(name: str) -> Path:
    try:
        return vendor_gripper(name)
    except AssetFetchError as exc:
        pytest.skip(f"vendor gripper {name} is not cached and cannot be fetched: {exc}")


@pytest.fixture(scope="module")
def tagged(tmp_path_factory):
    """``tagged(name)`` -> (source, copy, preview, source hash before tagging)."""
    done: dict = {}
    out_dir = tmp_path_factory.mktemp("tagged")

    def get(name: str):
        if name not in done:
            src = vendor(name)
            before = sha(src)
            t0 = time.perf_counter()
            contacts = suggest_contacts(src, points=64)
            preview = tag_urdf(
                src, out_dir / f"{name}.urdf", contacts, approach=suggest_approach(src)
            )
            TIMINGS[name] = time.perf_counter() - t0
            done[name] = (src, preview.urdf_path, preview, before)
        return done[name]

    return get


# ----------------------------------------------------------- independent helpers
def resolve_by_hand(filename: str, urdf_dir: Path) -> Path:
    """Where a vendor mesh name points: relative to the URDF, or ``package://pkg/rest`` as
    ``pkg/rest`` in the URDF's folder or an ancestor, or ``rest`` below an ancestor named pkg."""
    if not filename.startswith("package://"):
        return (urdf_dir / filename).resolve()
    pkg, _, rest = filename[len("package://") :].partition("/")
    for folder in (urdf_dir, *urdf_dir.parents):
        for cand in (folder / pkg / rest, folder / rest if folder.name == pkg else None):
            if cand is not None and cand.is_file():
                return cand
    raise AssertionError(f"cannot resolve {filename} from {urdf_dir}")


ISF_LINE = re.compile(r"^[ \t]*<isf:(gripper|contact|initial) [^\n]*/>\r?\n$")
FILENAME = re.compile(r'filename="([^"]*)"')


def assert_only_isf_changes(original: str, copy: str, src_dir: Path) -> tuple[int, int]:
    """The copy is the original plus the namespace, isf lines and absolute mesh paths.

    Returns:
        (number of isf lines, number of rewritten mesh lines).
    """
    a = original.splitlines(keepends=True)
    b = copy.splitlines(keepends=True)
    n_isf = 0
    n_mesh = 0
    for op, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes():
        if op == "equal":
            continue
        assert op in ("insert", "replace"), f"lines deleted from the vendor text: {a[i1:i2]}"
        new = b[j1:j2]
        added = [ln for ln in new if ISF_LINE.match(ln)]
        n_isf += len(added)
        changed = [ln for ln in new if not ISF_LINE.match(ln)]
        assert len(changed) == i2 - i1, f"unexpected lines {changed} for {a[i1:i2]}"
        for old_line, new_line in zip(a[i1:i2], changed):
            if ISF_XMLNS in new_line and "<robot" in new_line:
                assert new_line.replace(ISF_XMLNS, "", 1) == old_line
                continue
            old_names, new_names = FILENAME.findall(old_line), FILENAME.findall(new_line)
            assert len(old_names) == len(new_names) == 1, f"{old_line!r} -> {new_line!r}"
            assert FILENAME.sub("", old_line) == FILENAME.sub("", new_line)
            new_path = Path(new_names[0])
            assert new_path.is_absolute()
            assert os.path.samefile(new_path, resolve_by_hand(old_names[0], src_dir))
            n_mesh += 1
    return n_isf, n_mesh


def surface_frames(gripper: isf.Gripper, q: np.ndarray):
    """Per surface: centroid and unit mean normal of its loaded points, gripper frame."""
    points, normals = gripper.contact_points(q)
    out = {}
    for k, s in enumerate(gripper.surfaces):
        sel = gripper.point_surface == k
        n = normals[sel].mean(axis=0)
        out[s.name] = (s.link, points[sel].mean(axis=0), n / np.linalg.norm(n), points[sel])
    return out


# ------------------------------------------------------------------- vendor files
@pytest.mark.parametrize("name", sorted(FINGERTIPS))
def test_suggest_and_tag_vendor_gripper(name, tagged):
    src, out, preview, before = tagged(name)
    assert sha(src) == before, "the vendor file changed"
    assert preview.ok, preview.problems
    assert preview.source_path == src.resolve() and out != src
    gripper = isf.load_gripper(out)
    assert {s.link for s in gripper.surfaces} == FINGERTIPS[name]
    assert [s.name for s in preview.surfaces] == [s.name for s in gripper.surfaces]
    for s in preview.surfaces:
        assert 0 < s.n_faces <= s.n_faces_total and s.area > 0 and not s.problems
    # the preview's centroid (own FK, area-weighted faces) matches the loaded points' mean
    # within 4 standard errors of a mean of n uniform samples over a patch of that area
    frames = surface_frames(gripper, gripper.q_initial)
    for s in preview.surfaces:
        n = len(frames[s.name][3])
        tol = 4 * np.sqrt(s.area / (12 * n)) * np.sqrt(3)
        assert np.linalg.norm(s.centroid_gripper - frames[s.name][1]) < tol
    assert TIMINGS[name] < 5.0


@pytest.mark.parametrize("name", sorted(FINGERTIPS))
def test_copy_differs_only_by_isf_tags(name, tagged):
    src, out, preview, _ = tagged(name)
    original = src.read_text(encoding="utf-8")
    copy = out.read_text(encoding="utf-8")
    n_isf, n_mesh = assert_only_isf_changes(original, copy, src.parent)
    assert n_isf == 1 + len(FINGERTIPS[name])  # <isf:gripper approach> + one contact each
    assert n_mesh == len(re.findall(r"<mesh\b", original))  # the copy lives elsewhere
    assert set(preview.rewritten_meshes) == set(FILENAME.findall(original))
    assert preview.namespace_added
    # no other namespace appears: Robotiq's undeclared drake: prefix stays undeclared
    assert re.findall(r"xmlns:(\w+)", copy) == re.findall(r"xmlns:(\w+)", original) + ["isf"]
    assert copy.count("<drake:") == original.count("<drake:")


ROUNDED_TIPS = {"allegro-right"}  # hemispherical fingertips, no flat pad


def _last_joint_axis(urdf: Path, link: str, poses: dict) -> np.ndarray:
    """Axis (gripper frame) of the last movable joint above ``link``, read from the URDF text."""
    import xml.etree.ElementTree as ET

    joints = {j.find("child").get("link"): j for j in ET.parse(urdf).getroot().iter("joint")}
    while joints[link].get("type") == "fixed":
        link = joints[link].find("parent").get("link")
    axis = np.array([float(v) for v in joints[link].find("axis").get("xyz").split()])
    return poses[link][:3, :3] @ axis / np.linalg.norm(axis)  # the axis is in the child frame


@pytest.mark.parametrize("name", sorted(FINGERTIPS))
def test_pads_face_the_other_fingers(name, tagged):
    """Flat pads face the other fingers; a rounded tip faces their side with the component
    along its finger's last joint axis removed (it faces the way the finger curls)."""
    src, out, _, _ = tagged(name)
    gripper = isf.load_gripper(out)
    frames = surface_frames(gripper, gripper.q_initial)
    poses = gripper.link_poses(gripper.q_initial)
    for surface, (link, c, n, _) in frames.items():
        others = np.mean([f[1] for k, f in frames.items() if k != surface], axis=0)
        toward = (others - c) / np.linalg.norm(others - c)
        if name in ROUNDED_TIPS:
            axis = _last_joint_axis(Path(src), link, poses)
            assert abs(n @ axis) < 0.1, (surface, n, axis)  # mean normal of the sampled cap
            expected = toward - (toward @ axis) * axis
            assert n @ (expected / np.linalg.norm(expected)) > 0.9, (surface, n, toward)
        else:
            assert n @ toward > 0.7, (surface, n, toward)


@pytest.mark.parametrize("name", sorted(CLOSING_AXIS))
def test_parallel_pads_are_the_innermost_faces(name, tagged):
    """Pads of a parallel jaw are antiparallel and are the finger's face nearest the other
    finger (checked against every vertex of the finger's collision geometry)."""
    _, out, _, _ = tagged(name)
    gripper = isf.load_gripper(out)
    q = gripper.q_initial
    frames = surface_frames(gripper, q)
    (a_link, a_c, a_n, a_pts), (b_link, b_c, b_n, b_pts) = frames.values()
    assert a_n @ b_n < -0.99
    poses = gripper.link_poses(q)
    axis = np.array(CLOSING_AXIS[name])
    for link, c, pts, other in ((a_link, a_c, a_pts, b_c), (b_link, b_c, b_pts, a_c)):
        u = axis * np.sign(axis @ (other - c))
        verts = [
            g.vertices @ poses[link][:3, :3].T + poses[link][:3, 3]
            for g in gripper.geometries
            if g.link == link
        ]
        front = max(float((v @ u).max()) for v in verts)
        assert np.all(pts @ u > front - 5e-4), link


def test_suggested_approach_matches_the_finger_axis():
    # Franka: fingers slide along y and stick out along +z of the hand frame (joint origin
    # z = 0.0584); PR2: the fingers hinge about z at x = 0.2 and point along +x.
    assert np.allclose(suggest_approach(vendor("franka-hand")), (0, 0, 1), atol=1e-6)
    pr2 = np.array(suggest_approach(vendor("pr2-gripper")))
    assert pr2[0] > 0.99


# ---------------------------------------------------------------- mesh paths
def test_copy_beside_the_source_keeps_mesh_paths(tmp_path):
    src = vendor("pr2-gripper")
    folder = tmp_path / "pr2"
    folder.mkdir()
    for name in ("pr2_gripper.urdf", "l_finger_collision.stl", "l_finger_tip.stl"):
        shutil.copy(src.parent / name, folder / name)
    local = folder / "pr2_gripper.urdf"
    preview = tag_urdf(local, folder / "pr2_isf.urdf", suggest_contacts(local))
    assert preview.ok, preview.problems
    assert preview.rewritten_meshes == {}
    n_isf, n_mesh = assert_only_isf_changes(
        local.read_text(), preview.urdf_path.read_text(), folder
    )
    assert (n_isf, n_mesh) == (2, 0)  # no <isf:gripper>: neither palm_link nor approach given


def test_package_map_is_resolved_into_absolute_paths(tmp_path):
    """A source that needs package_dirs gives a copy that loads without one."""
    src = vendor("franka-hand")
    lone = tmp_path / "lone" / "hand.urdf"  # the URDF without its meshes folder
    lone.parent.mkdir()
    shutil.copy(src, lone)
    assert not isf.inspect_gripper(lone).ok  # meshes not found
    meshes = {"meshes": src.parent / "meshes"}
    contacts = suggest_contacts(lone, package_dirs=meshes)
    preview = tag_urdf(lone, tmp_path / "out" / "hand.urdf", contacts, package_dirs=meshes)
    assert preview.ok, preview.problems
    for old, new in preview.rewritten_meshes.items():
        assert os.path.samefile(new, src.parent / old[len("package://") :])
    isf.load_gripper(preview.urdf_path)


# ------------------------------------------------------------------ namespace
def test_existing_namespace_and_existing_tags(tmp_path, tagged):
    src, first, _, _ = tagged("franka-hand")
    # a source that declares xmlns:isf (correctly) but has no tags: declaration kept as is
    declared = tmp_path / "declared" / "hand.urdf"
    declared.parent.mkdir()
    text = src.read_text().replace('<robot name="panda"', '<robot name="panda"' + ISF_XMLNS)
    declared.write_text(text)
    contacts = suggest_contacts(src)
    preview = tag_urdf(
        declared,
        tmp_path / "declared" / "copy.urdf",
        contacts,
        package_dirs={"meshes": src.parent / "meshes"},
    )
    assert preview.ok and not preview.namespace_added
    assert preview.urdf_path.read_text().count("xmlns:isf") == 1
    # a file that is tagged already: refused, or re-tagged with replace_tags
    with pytest.raises(RegistrationError, match="replace_tags"):
        tag_urdf(first, tmp_path / "again.urdf", contacts)
    one = [dataclasses.replace(contacts[0], name="only")]
    again = tag_urdf(first, tmp_path / "again.urdf", one, replace_tags=True)
    assert again.ok and [s.name for s in again.surfaces] == ["only"]
    assert again.urdf_path.read_text().count("<isf:") == 1
    # a wrong namespace URI is refused with the fix
    wrong = tmp_path / "wrong.urdf"
    wrong.write_text(text.replace("urn:isf:gripper:1", "urn:other"))
    with pytest.raises(RegistrationError, match="bind it to"):
        tag_urdf(wrong, tmp_path / "w.urdf", contacts)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(normal=(0, 0, 0)), "zero vector"),
        (dict(normal=(1, 0)), "3 finite numbers"),
        (dict(max_angle=0.0), "max_angle"),
        (dict(points=0), "points"),
        (dict(source="mesh"), "source"),
        (dict(box_min=(0, 0, 1), box_max=(1, 1, 0)), "swap"),
        (dict(name=""), "name"),
    ],
)
def test_contact_spec_rejects_bad_values(kwargs, message):
    args = dict(name="pad", link="left_finger") | kwargs
    with pytest.raises(RegistrationError, match=message):
        ContactSpec(**args)


def test_bad_tagging_requests(tmp_path):
    src = vendor("pr2-gripper")
    before = sha(src)
    pad = ContactSpec("pad", "left_tip", normal=(0, -1, 0))
    with pytest.raises(RegistrationError, match="source file"):
        tag_urdf(src, src, [pad])
    with pytest.raises(RegistrationError, match="more than once"):
        tag_urdf(src, tmp_path / "d.urdf", [pad, pad])
    with pytest.raises(RegistrationError, match="non-empty"):
        tag_urdf(src, tmp_path / "e.urdf", [])
    assert sha(src) == before
    # mistakes in the tags themselves are reported by the validation, not raised
    preview = tag_urdf(
        src,
        tmp_path / "p.urdf",
        [
            pad,
            ContactSpec("ghost", "no_such_link"),
            ContactSpec("empty", "right_tip", normal=(0, 0, 1), max_angle=0.1, box_min=(1, 1, 1)),
        ],
    )
    assert not preview.ok
    by_name = {s.name: s for s in preview.surfaces}
    assert by_name["pad"].n_faces > 0 and not by_name["pad"].problems
    assert by_name["empty"].n_faces == 0 and "keeps no face" in by_name["empty"].problems[0]
    assert any("no_such_link" in p for p in preview.problems)
    with pytest.raises(isf.GripperDescriptionError):
        isf.load_gripper(preview.urdf_path)
    with pytest.raises(RegistrationError, match="do not exist"):
        suggest_contacts(src, links=["nope"])
    with pytest.raises(RegistrationError, match="at least two"):
        suggest_contacts(src, links=["left_tip"])


def test_links_override_and_initial_configuration():
    src = vendor("robotiq-2f-85")
    specs = suggest_contacts(src, links=["left_inner_finger_pad", "right_inner_finger_pad"])
    assert [s.link for s in specs] == ["left_inner_finger_pad", "right_inner_finger_pad"]
    # nearly closed (finger_joint = 0.8 rad closes the jaw) the pads still face each other
    closed = suggest_contacts(src, initial={"finger_joint": 0.7})
    assert [s.normal for s in closed] == [s.normal for s in specs]


# --------------------------------------------------------------------- preview
def test_format_and_export_show_the_selection(tmp_path, tagged):
    _, _, preview, _ = tagged("franka-hand")
    text = preview.format()
    for s in preview.surfaces:
        assert f"{s.name}: link {s.link!r}" in text
        assert f"{s.n_faces}/{s.n_faces_total} faces" in text
    assert "OK (checked in" in text and "made absolute" in text
    out = preview.export(tmp_path / "preview.ply")
    mesh = trimesh.load(out, process=False)
    red = np.all(mesh.visual.face_colors[:, :3] == (220, 30, 30), axis=1)
    assert red.sum() == sum(s.n_faces for s in preview.surfaces)


# ------------------------------------------------------------------- planning
def ycb(name: str):
    try:
        return benchmark_object(name)
    except YCBNotFoundError as exc:
        pytest.skip(f"YCB meshes absent ({exc})")


@pytest.mark.slow
def test_franka_plans_a_collision_free_grasp_on_ycb(tagged):
    entry = ycb(YCB_OBJECT)
    _, out, _, _ = tagged("franka-hand")
    gripper = isf.load_gripper(out)
    mesh = trimesh.load(entry.path, force="mesh")
    result = isf.plan(gripper, isf.load_object(entry.path), samples=20, seed=0)
    best = result.best
    assert best.collision_free and best.fit.all_surfaces_in_contact
    assert best.fit.mean_distance < 2e-3
    # independent check with trimesh on the YCB mesh: the pads lie on the object...
    T = best.T_object_gripper
    frames = surface_frames(gripper, best.q)
    for _, (_, _, _, pts) in frames.items():
        p_obj = pts @ T[:3, :3].T + T[:3, 3]
        _, dist, _ = trimesh.proximity.closest_point(mesh, p_obj)
        assert np.median(dist) < 2e-3
    # ...and no part of the hand is inside it deeper than the 2 mm tolerance
    poses = gripper.link_poses(best.q)
    for g in gripper.geometries:
        part = trimesh.Trimesh(g.vertices, g.faces, process=False)
        samples = np.concatenate([part.sample(300, seed=1), part.vertices])
        T_obj_link = T @ poses[g.link]
        depth = trimesh.proximity.signed_distance(
            mesh, samples @ T_obj_link[:3, :3].T + T_obj_link[:3, 3]
        )
        assert depth.max() < 2.5e-3, g.link  # positive inside


def python_blocks(markdown: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", markdown, flags=re.DOTALL | re.MULTILINE)


@pytest.mark.slow
def test_tutorial_runs(tmp_path, monkeypatch, capsys):
    entry = ycb(YCB_OBJECT)  # the tutorial's last step needs the YCB folder
    vendor("franka-hand")
    blocks = python_blocks(TUTORIAL.read_text(encoding="utf-8"))
    assert len(blocks) >= 5
    monkeypatch.setenv("ISF_YCB_DIR", str(entry.path.parent))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__tutorial__"}
    for k, block in enumerate(blocks):
        exec(compile(block, f"{TUTORIAL.name}[python block {k}]", "exec"), namespace)
    printed = capsys.readouterr().out
    assert (tmp_path / "franka_hand_isf.urdf").is_file()
    assert (tmp_path / "franka_hand_isf_preview.ply").is_file()
    assert "best grasp: collision-free True" in printed
    assert namespace["best"].fit.mean_distance < 2e-3


def test_contact_spec_parse_round_trips_through_the_tag():
    spec = ContactSpec.parse(
        "name=left link=left_finger normal=0,-2,0 max_angle=0.3 box_min=-1,-1,0.03 points=64"
    )
    expected = ContactSpec(
        "left", "left_finger", normal=(0, -2, 0), max_angle=0.3, box_min=(-1, -1, 0.03), points=64
    )
    assert spec == expected
    assert spec.to_xml() == (
        '<isf:contact name="left" link="left_finger" normal="0 -2 0" max_angle="0.3" '
        'box_min="-1 -1 0.03" points="64"/>'
    )
    bad = {
        "name=a": "needs link",
        "name=a link=b colour=red": "key=value",
        "name=a link=b normal=1,2": "3 finite",
        "name=a link=b flip=yes": "bad value",
    }
    for text, message in bad.items():
        with pytest.raises(RegistrationError, match=message):
            ContactSpec.parse(text)


# A small hand-written URDF with unusual but valid formatting: CRLF line ends, a '>' inside
# an attribute of <robot>, a commented-out mesh and </robot>, a single-quoted mesh filename
# holding an XML entity, and </robot> on the same line as other content.
ODD_URDF = (
    '<?xml version="1.0"?>\r\n'
    '<!-- <robot name="decoy"> -->\r\n'
    '<robot name="odd > name"\r\n       xmlns:foo="urn:foo">\r\n'
    '  <link name="palm"><collision><geometry><box size="0.06 0.02 0.02"/></geometry>'
    "</collision></link>\r\n"
    '  <link name="left"><collision><origin xyz="0 0.005 0.02"/><geometry>'
    "<mesh filename='meshes/pad&amp;1.stl'/></geometry></collision></link>\r\n"
    '  <link name="right"><collision><origin xyz="0 -0.005 0.02"/><geometry>'
    '<box size="0.01 0.01 0.04"/></geometry></collision></link>\r\n'
    '  <joint name="l" type="prismatic"><parent link="palm"/><child link="left"/>'
    '<origin xyz="0 0.01 0.03"/><axis xyz="0 1 0"/>'
    '<limit lower="0" upper="0.03" effort="1" velocity="1"/></joint>\r\n'
    '  <joint name="r" type="prismatic"><parent link="palm"/><child link="right"/>'
    '<origin xyz="0 -0.01 0.03"/><axis xyz="0 -1 0"/>'
    '<limit lower="0" upper="0.03" effort="1" velocity="1"/>'
    '<mimic joint="l"/></joint>\r\n'
    '  <!-- <mesh filename="gone.stl"/> </robot> -->\r\n'
    "  <foo:note text='kept'/></robot>\r\n"
)


def test_text_edits_survive_unusual_formatting(tmp_path):
    src_dir = tmp_path / "vendor"
    (src_dir / "meshes").mkdir(parents=True)
    trimesh.creation.box(extents=(0.01, 0.01, 0.04)).export(src_dir / "meshes" / "pad&1.stl")
    src = src_dir / "odd.urdf"
    src.write_bytes(ODD_URDF.encode())
    specs = suggest_contacts(src)
    assert {s.link for s in specs} == {"left", "right"}
    assert specs[0].normal == (0.0, -1.0, 0.0) and specs[1].normal == (0.0, 1.0, 0.0)
    preview = tag_urdf(src, tmp_path / "out" / "odd.urdf", specs, initial={"l": 0.01})
    assert preview.ok, preview.problems
    assert src.read_bytes() == ODD_URDF.encode()
    copy = preview.urdf_path.read_bytes().decode()
    absolute = str(src_dir / "meshes" / "pad&1.stl").replace("&", "&amp;")
    expected_head = ODD_URDF.replace(
        '"urn:foo">', '"urn:foo"' + ISF_XMLNS + ">", 1
    ).replace("meshes/pad&amp;1.stl", absolute)
    body, tail = expected_head.rsplit("</robot>", 1)
    inserted = copy[len(body) : len(copy) - len("</robot>" + tail)]
    assert copy.startswith(body) and copy.endswith("</robot>" + tail)
    lines = inserted.split("\r\n")
    assert lines[0] == "" and lines[-1] == ""  # on lines of their own, CRLF like the file
    assert [ln.split()[0] for ln in lines[1:-1]] == ["<isf:contact"] * 2 + ["<isf:initial"]
    assert all(ln.startswith("  <isf:") for ln in lines[1:-1])
    gripper = isf.load_gripper(preview.urdf_path)
    assert np.allclose(gripper.q_initial, [0.01])
