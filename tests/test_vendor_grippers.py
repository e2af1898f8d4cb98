"""Stock vendor URDFs (fetched by :mod:`isf.assets`) as isf reads and loads them.

Expectations come from outside isf: the vendor file itself, read by the small
ElementTree reader below (it shares no code with :mod:`isf.gripper.urdf_tags`), the raw
mesh files read by trimesh, and yourdfpy's forward kinematics (a second
implementation that handles mimic joints itself).

The cache is never written: a tagged copy lives in ``tmp_path`` and reaches the
vendor meshes through a symlink (Robotiq, PR2) or ``package_dirs`` (Franka, Allegro).
:func:`tagged_vendor_gripper` is also used by ``test_jacobians_real.py``.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import trimesh
import yourdfpy

from isf import assets
from isf.gripper.loading import inspect_gripper, load_gripper
from isf.gripper.model import Gripper

VENDORS = ("franka-hand", "robotiq-2f-85", "allegro-right", "pr2-gripper")
ISF_NS = "urn:isf:gripper:1"  # docs/gripper-tags.md

# Facts about the vendor files, read off the files by eye: (actuated, mimic, type of every
# moving joint, limits shared by all moving joints or None).
EXPECTED = {
    "franka-hand": (1, 1, "prismatic", (0.0, 0.04)),
    "robotiq-2f-85": (1, 5, "revolute", None),
    "allegro-right": (16, 0, "revolute", None),
    "pr2-gripper": (2, 0, "revolute", (0.0, 0.548)),
}

# Contact tags of the tagged copies. Normals are link-frame directions chosen from the
# vendor geometry:
# * Franka: finger.obj spans y in [0, 26] mm with its flat pad face at y = 0 (normal -y);
#   the right finger's collision is the same mesh turned by pi about z, so its pad faces +y.
# * Robotiq: the pad is a box 22 x 6.35 x 37.5 mm; its -y face looks at the other pad.
# * Allegro: fingertips are 12 mm hemispheres (visual STL, metres); the fingers curl about
#   +y towards +x, so +x in the tip frame is the palmar side of every tip, the thumb's too.
# * PR2: the left fingertip box's -y face and the right one's +y face look at each other
#   (the right tip has a second, tilted box, left out with geometry=).
TAGS = {
    "franka-hand": [
        ("left_pad", "left_finger", 'normal="0 -1 0" max_angle="0.3"'),
        ("right_pad", "right_finger", 'normal="0 1 0" max_angle="0.3"'),
    ],
    "robotiq-2f-85": [
        ("left_pad", "left_inner_finger_pad", 'normal="0 -1 0" max_angle="0.3"'),
        ("right_pad", "right_inner_finger_pad", 'normal="0 -1 0" max_angle="0.3"'),
    ],
    "allegro-right": [
        (f"tip{k}", f"link_{k}.0_tip", 'source="visual" normal="1 0 0" max_angle="0.8"')
        for k in (3, 7, 11, 15)
    ],
    "pr2-gripper": [
        ("left_tip", "left_tip", 'normal="0 -1 0" max_angle="0.3"'),
        ("right_tip", "right_tip", 'geometry="right_tip_0" normal="0 1 0" max_angle="0.3"'),
    ],
}

# (a, b): surface a's mean normal must point at surface b's centroid when the hand is open.
FACING = {
    "franka-hand": [("left_pad", "right_pad"), ("right_pad", "left_pad")],
    "robotiq-2f-85": [("left_pad", "right_pad"), ("right_pad", "left_pad")],
    "allegro-right": [("tip3", "tip15"), ("tip7", "tip15"), ("tip11", "tip15"), ("tip15", "tip7")],
    "pr2-gripper": [("left_tip", "right_tip"), ("right_tip", "left_tip")],
}

# Surfaces that are one face of a vendor <box>: their area is that face's area, m^2.
BOX_FACE_AREAS = {
    "robotiq-2f-85": {"left_pad": 0.022 * 0.0375, "right_pad": 0.022 * 0.0375},
    "pr2-gripper": {"left_tip": 0.03 * 0.02, "right_tip": 0.03 * 0.02},
}


# ----------------------------------------------------------- independent reader
@dataclass(frozen=True)
class RefJoint:
    type: str
    parent: str
    child: str
    lower: float | None
    upper: float | None
    mimic: tuple[str, float, float] | None  # (leader, multiplier, offset)


@dataclass(frozen=True)
class RefMesh:
    link: str
    source: str
    element: str
    filename: str
    scale: np.ndarray
    used: bool  # the link's collisions, or its visuals when it has no collision


@dataclass(frozen=True)
class RefURDF:
    links: list[str]
    joints: dict[str, RefJoint]
    meshes: list[RefMesh]

    @property
    def root(self) -> str:
        children = {j.child for j in self.joints.values()}
        (root,) = [link for link in self.links if link not in children]
        return root


def declared_text(path: Path) -> str:
    """The file's text with every undeclared XML prefix (Robotiq's ``drake:``) declared."""
    text = path.read_text(encoding="utf-8")
    used = set(re.findall(r"</?([A-Za-z_][\w.\-]*):", text))
    missing = sorted(used - set(re.findall(r"xmlns:([A-Za-z_][\w.\-]*)=", text)))
    decl = "".join(f' xmlns:{p}="urn:test:{p}"' for p in missing)
    return re.sub(r"<robot\b", "<robot" + decl, text, count=1)


def _float(elem: ET.Element | None, attr: str) -> float | None:
    return None if elem is None or elem.get(attr) is None else float(elem.get(attr))


def read_reference(path: Path) -> RefURDF:
    """Links, joints and mesh elements of a URDF, read with ElementTree only."""
    root = ET.fromstring(declared_text(path))
    links, meshes = [], []
    for link in root.findall("link"):
        name = link.get("name")
        links.append(name)
        collisions = link.findall("collision")
        for source in ("collision", "visual"):
            used = source == "collision" or not collisions
            for k, elem in enumerate(link.findall(source)):
                mesh = elem.find("geometry/mesh")
                if mesh is not None:
                    scale = np.array([float(v) for v in mesh.get("scale", "1 1 1").split()])
                    element = elem.get("name") or f"{name}_{k}"
                    meshes.append(RefMesh(name, source, element, mesh.get("filename"), scale, used))
    joints = {}
    for joint in root.findall("joint"):
        limit, m = joint.find("limit"), joint.find("mimic")
        mimic = None
        if m is not None:  # URDF defaults: multiplier 1, offset 0
            mimic = (m.get("joint"), float(m.get("multiplier", 1)), float(m.get("offset", 0)))
        joints[joint.get("name")] = RefJoint(
            joint.get("type"),
            joint.find("parent").get("link"),
            joint.find("child").get("link"),
            _float(limit, "lower"),
            _float(limit, "upper"),
            mimic,
        )
    return RefURDF(links, joints, meshes)


def resolve_reference(filename: str, urdf_dir: Path, package_dirs: dict | None = None) -> Path:
    """A mesh filename as ROS tools find it: package map, then ancestor folders named ``pkg``."""
    if not filename.startswith("package://"):
        return urdf_dir / filename
    pkg, _, rest = filename[len("package://") :].partition("/")
    if package_dirs and pkg in package_dirs:
        return Path(package_dirs[pkg]) / rest
    for folder in (urdf_dir, *urdf_dir.parents):
        if folder.name == pkg:
            return folder / rest
        if (folder / pkg).is_dir():
            return folder / pkg / rest
    raise FileNotFoundError(filename)


# ------------------------------------------------------------------ fixtures
def stock_urdf(name: str) -> Path:
    """The cached vendor URDF; skips (saying why) when it cannot be fetched."""
    try:
        return assets.vendor_gripper(name)
    except assets.AssetFetchError as exc:
        pytest.skip(f"vendor gripper {name!r} is not cached and cannot be fetched: {exc}")


def _write_tagged(stock: Path, dest: Path, tags: list[tuple[str, str, str]]) -> Path:
    text = stock.read_text(encoding="utf-8")
    text = re.sub(r"<robot\b", f'<robot xmlns:isf="{ISF_NS}"', text, count=1)
    lines = "".join(f'  <isf:contact name="{n}" link="{lk}" {more}/>\n' for n, lk, more in tags)
    end = text.rindex("</robot>")
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(text[:end] + lines + text[end:], encoding="utf-8")
    return dest


def tagged_vendor_gripper(
    name: str, folder: Path, extra_tags: tuple[tuple[str, str, str], ...] = ()
) -> tuple[Path, dict[str, Path]]:
    """Write a tagged copy of a vendor URDF into ``folder``; return it and its package_dirs.

    The copy carries the contact tags of ``TAGS[name]`` plus ``extra_tags``, each
    ``(surface name, link, further attributes)``. Only ``folder`` is written; the
    vendor meshes are reached by symlink or package map.
    """
    stock = stock_urdf(name)
    tags = [*TAGS[name], *extra_tags]
    if name == "franka-hand":  # package://meshes/...: map the package to the vendor folder
        return _write_tagged(stock, folder / stock.name, tags), {
            "meshes": stock.parent / "meshes"
        }
    if name == "robotiq-2f-85":  # ../meshes/...: same layout, meshes folder symlinked
        (folder / "meshes").symlink_to(stock.parent.parent / "meshes", target_is_directory=True)
        return _write_tagged(stock, folder / "urdf" / stock.name, tags), {}
    if name == "allegro-right":  # package://example-robot-data/robots/...
        share = next(p for p in stock.parents if p.name == "example-robot-data")
        return _write_tagged(stock, folder / stock.name, tags), {"example-robot-data": share}
    if name == "pr2-gripper":  # bare file names beside the URDF: symlink each mesh
        for filename in {m.filename for m in read_reference(stock).meshes}:
            (folder / filename).symlink_to(stock.parent / filename)
        return _write_tagged(stock, folder / stock.name, tags), {}
    raise ValueError(name)


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for dirpath, _, files in os.walk(folder):
        for f in files:
            st = os.lstat(os.path.join(dirpath, f))
            out[os.path.relpath(os.path.join(dirpath, f), folder)] = (st.st_size, st.st_mtime_ns)
    return out


@dataclass(frozen=True)
class Tagged:
    """A loaded tagged copy; ``cache_before/after``: the vendor folder around the load."""

    stock: Path
    copy: Path
    package_dirs: dict
    gripper: Gripper
    cache_before: dict
    cache_after: dict


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """``loaded(name)``: the vendor's :class:`Tagged` copy, built once per module."""
    built: dict[str, Tagged] = {}

    def get(name: str) -> Tagged:
        if name not in built:
            stock = stock_urdf(name)
            before = _snapshot(stock.parent.parent)
            copy, pkg = tagged_vendor_gripper(name, tmp_path_factory.mktemp(name))
            gripper = load_gripper(copy, package_dirs=pkg)
            built[name] = Tagged(stock, copy, pkg, gripper, before, _snapshot(stock.parent.parent))
        return built[name]

    return get


@pytest.fixture(scope="module")
def reference_fk(tmp_path_factory):
    """yourdfpy model of the stock file (undeclared prefixes declared, meshes not loaded)."""
    models: dict = {}

    def get(name: str) -> yourdfpy.URDF:
        if name not in models:
            path = tmp_path_factory.mktemp(f"{name}-ref") / "reference.urdf"
            path.write_text(declared_text(stock_urdf(name)), encoding="utf-8")
            models[name] = yourdfpy.URDF.load(str(path), build_scene_graph=True, load_meshes=False)
        return models[name]

    return get


# ---------------------------------------------------------- the stock files
@pytest.mark.parametrize("name", VENDORS)
def test_stock_file_inspects_as_elementtree_reads_it(name):
    path = stock_urdf(name)
    ref = read_reference(path)
    report = inspect_gripper(path)

    assert report.urdf_path == path.resolve()
    assert list(report.links) == ref.links
    assert report.root_link == ref.root
    assert [j.name for j in report.joints] == list(ref.joints)
    for j in report.joints:
        r = ref.joints[j.name]
        assert (j.type, j.parent, j.child) == (r.type, r.parent, r.child), j.name
        assert (j.lower, j.upper) == (r.lower, r.upper), j.name
        mimic = (j.mimic_leader, j.mimic_multiplier, j.mimic_offset)
        assert (None if j.mimic_leader is None else mimic) == r.mimic, j.name
        assert j.actuated == (r.type in ("revolute", "prismatic") and r.mimic is None), j.name

    n_actuated, n_mimic, moving_type, limits = EXPECTED[name]
    moving = [j for j in report.joints if j.type != "fixed"]
    assert sum(j.actuated for j in report.joints) == n_actuated
    assert sum(j.mimic_leader is not None for j in report.joints) == n_mimic
    assert {j.type for j in moving} == {moving_type}
    assert all(j.lower is not None and j.lower < j.upper for j in moving)
    if limits is not None:
        assert all((j.lower, j.upper) == limits for j in moving)

    # every <mesh> element is reported, found where the vendor put it, and flagged as used
    # exactly when it belongs to the geometry isf reads (collisions, else visuals)
    got = sorted((m.link, m.source, m.element, m.filename, m.used) for m in report.meshes)
    want = sorted((m.link, m.source, m.element, m.filename, m.used) for m in ref.meshes)
    assert got == want
    for m in report.meshes:
        assert m.found, m.filename
        assert m.path.samefile(resolve_reference(m.filename, path.parent)), m.filename

    assert len(report.problems) == 1 and "<isf:contact>" in report.problems[0], report.problems
    assert not report.ok


def test_allegro_tip_meshes_resolve_only_through_package_dirs(loaded):
    t = loaded("allegro-right")
    assert inspect_gripper(t.copy, package_dirs=t.package_dirs).ok
    # the copy's folder has no example-robot-data ancestor: without the map nothing is found
    problems = inspect_gripper(t.copy).problems
    assert len(problems) == 4 and all("not found" in p for p in problems), problems
    assert {s.link for s in t.gripper.surfaces} == {f"link_{k}.0_tip" for k in (3, 7, 11, 15)}


# ------------------------------------------------------------- tagged copies
@pytest.mark.parametrize("name", VENDORS)
def test_tagged_copy_loads_with_sensible_surfaces(name, loaded):
    t = loaded(name)
    stock, gripper = t.stock, t.gripper
    assert not t.copy.resolve().is_relative_to(stock.parent.parent.resolve())
    assert t.cache_after == t.cache_before, "loading the tagged copy changed the vendor cache"
    ref = read_reference(stock)
    actuated = [n for n, j in ref.joints.items() if j.type != "fixed" and j.mimic is None]
    assert sorted(gripper.joint_names) == sorted(actuated)
    for k, j in enumerate(gripper.joint_names):
        assert (gripper.lower[k], gripper.upper[k]) == (ref.joints[j].lower, ref.joints[j].upper)
    assert [s.name for s in gripper.surfaces] == [t[0] for t in TAGS[name]]
    for s in gripper.surfaces:
        assert len(s.points) == 256 and s.area > 0
        np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, atol=1e-12)
    for surface, area in BOX_FACE_AREAS.get(name, {}).items():
        (s,) = [s for s in gripper.surfaces if s.name == surface]
        assert s.area == pytest.approx(area, rel=1e-9), surface

    kin = gripper.contact_kinematics(gripper.q_initial)
    index = {s.name: k for k, s in enumerate(gripper.surfaces)}
    for a, b in FACING[name]:
        pa = kin.points[gripper.point_surface == index[a]]
        na = kin.normals[gripper.point_surface == index[a]].mean(axis=0)
        d = kin.points[gripper.point_surface == index[b]].mean(axis=0) - pa.mean(axis=0)
        cos = na @ d / (np.linalg.norm(na) * np.linalg.norm(d))
        assert cos > 0.3, f"{a} does not face {b} (cos {cos:.2f})"


@pytest.mark.parametrize("name", VENDORS)
def test_link_poses_match_yourdfpy(name, loaded, reference_fk):
    gripper = loaded(name).gripper
    urdf = reference_fk(name)
    assert set(urdf.actuated_joint_names) == set(gripper.joint_names)
    poses = gripper.link_poses(gripper.q_initial)
    assert set(urdf.link_map) <= set(poses)
    rng = np.random.default_rng(11)
    random = rng.uniform(gripper.lower, gripper.upper, (3, gripper.n_joints))
    for q in (gripper.lower, gripper.upper, *random):
        urdf.update_cfg(gripper.joints(q))
        poses = gripper.link_poses(q)
        for link in urdf.link_map:
            np.testing.assert_allclose(
                poses[link], urdf.get_transform(link, urdf.base_link), atol=1e-9, err_msg=link
            )


def test_robotiq_mesh_scale_is_applied(loaded):
    t = loaded("robotiq-2f-85")
    meshes = read_reference(t.stock).meshes
    ref = {(m.link, m.element): m for m in meshes if m.source == "collision"}
    scaled = 0
    for geo in t.gripper.geometries:
        extent = np.ptp(geo.vertices, axis=0)
        assert 0.005 < extent.max() < 0.15, (geo.name, extent)  # centimetres, not metres or mm
        m = ref.get((geo.link, geo.name))
        if m is None:  # the pads are boxes
            continue
        raw_path = resolve_reference(m.filename, t.copy.parent, t.package_dirs)
        raw = trimesh.load(raw_path, force="mesh", process=False)
        np.testing.assert_allclose(extent, np.ptp(raw.vertices, axis=0) * m.scale, rtol=1e-9)
        scaled += bool(np.all(m.scale == 0.001))
    # knuckles and fingers, outer and inner, left and right: 8 meshes in mm; the base in metres
    assert scaled == 8


def test_robotiq_single_joint_moves_every_finger_link(loaded, reference_fk):
    gripper = loaded("robotiq-2f-85").gripper
    assert gripper.joint_names == ("finger_joint",)
    urdf = reference_fk("robotiq-2f-85")
    open_, closed = gripper.link_poses(gripper.lower), gripper.link_poses(gripper.upper)
    fingers = [link for link in urdf.link_map if link not in ("base_link", "base_link_inertia")]
    assert len(fingers) == 10
    for link in fingers:
        moved = np.linalg.norm(closed[link][:3, 3] - open_[link][:3, 3])
        cos = (np.trace(open_[link][:3, :3].T @ closed[link][:3, :3]) - 1) / 2
        turned = np.arccos(np.clip(cos, -1.0, 1.0))
        assert moved > 1e-3 or turned > 0.05, link
    for link in ("base_link", "base_link_inertia"):
        np.testing.assert_allclose(closed[link], open_[link], atol=1e-15)
    # the four-bar linkage keeps the pads parallel: they translate without turning
    for link in ("left_inner_finger_pad", "right_inner_finger_pad"):
        np.testing.assert_allclose(closed[link][:3, :3], open_[link][:3, :3], atol=1e-12)
        assert np.linalg.norm(closed[link][:3, 3] - open_[link][:3, 3]) > 0.03
    # the linkage closes the pads on each other: the 2F-85's 85 mm stroke down to ~0
    index = {s.name: k for k, s in enumerate(gripper.surfaces)}
    for q, lo, hi in ((gripper.lower, 0.08, 0.09), (gripper.upper, 0.0, 0.005)):
        kin = gripper.contact_kinematics(q)
        left = kin.points[gripper.point_surface == index["left_pad"]].mean(axis=0)
        right = kin.points[gripper.point_surface == index["right_pad"]].mean(axis=0)
        assert lo < np.linalg.norm(left - right) < hi, q
