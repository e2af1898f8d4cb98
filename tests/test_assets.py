"""Tests of isf.assets against the real vendor wheels (fetched once into the user cache).

The first run downloads five pinned wheels (about 490 MB through pip, ~30 s here) and keeps
44 MB of members in ``$ISF_CACHE_DIR`` or ``~/.cache/isf``; later runs only read the cache.
Checks use ElementTree and trimesh directly, never isf's own parsing.
"""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
import trimesh

from isf import assets
from isf.exceptions import ConfigError, ISFError


@pytest.fixture(scope="module")
def cache() -> dict[str, Path]:
    """Every pinned package's cache folder (downloads on the very first run only)."""
    return assets.prefetch()


def _parse_urdf(path: Path) -> ET.Element:
    text = path.read_text()
    if "drake:" in text and "xmlns:drake" not in text:  # Robotiq: undeclared namespace prefix
        text = text.replace("<robot ", '<robot xmlns:drake="urn:drake" ', 1)
    return ET.fromstring(text)


def _joints(root: ET.Element, jtype: str) -> list[ET.Element]:
    return [j for j in root.findall("joint") if j.get("type") == jtype]


def _mesh_files(root: ET.Element) -> list[str]:
    return [m.get("filename") for m in root.iter("mesh")]


# ------------------------------------------------------------------ real vendor grippers


def test_franka_hand_meshes_resolve_against_urdf_folder(cache):
    urdf = assets.vendor_gripper("franka-hand")
    assert urdf.name == "hand.urdf" and urdf.is_file()
    root = _parse_urdf(urdf)
    refs = _mesh_files(root)
    assert len(refs) == 6 and all(r.startswith("package://meshes/") for r in refs)
    for ref in refs:  # the data-sources notes: strip package:// and resolve in the URDF folder
        assert (urdf.parent / ref[len("package://") :]).is_file(), ref
    finger = trimesh.load(urdf.parent / "meshes/collision/finger.obj", force="mesh")
    assert 0.01 < finger.extents.max() < 0.1  # a Franka finger, in metres
    prismatic = _joints(root, "prismatic")
    assert len(prismatic) == 2 and sum(j.find("mimic") is not None for j in prismatic) == 1


def test_allegro_right_has_16_revolute_joints_and_package_meshes(cache):
    urdf = assets.vendor_gripper("allegro-right")
    root = _parse_urdf(urdf)
    revolute = _joints(root, "revolute")
    assert len(revolute) == 16
    assert all(j.find("mimic") is None for j in revolute)
    share = next(p for p in urdf.parents if p.name == "share")  # package dir of example-robot-data
    refs = _mesh_files(root)
    assert refs and all(r.startswith("package://example-robot-data/") for r in refs)
    for ref in refs:
        assert (share / ref[len("package://") :]).is_file(), ref


def test_robotiq_2f85_has_6_revolute_joints_5_mimic(cache):
    urdf = assets.vendor_gripper("robotiq-2f-85")
    root = _parse_urdf(urdf)
    revolute = _joints(root, "revolute")
    assert len(revolute) == 6
    mimics = [j for j in revolute if j.find("mimic") is not None]
    assert len(mimics) == 5
    assert {m.find("mimic").get("joint") for m in mimics} == {"finger_joint"}
    for ref in _mesh_files(root):
        assert (urdf.parent / ref).is_file(), ref


def test_pr2_gripper_and_panda_arm_meshes_present(cache):
    pr2 = assets.vendor_gripper("pr2-gripper")
    root = _parse_urdf(pr2)
    assert len(_joints(root, "revolute")) == 2
    for ref in _mesh_files(root):
        assert (pr2.parent / ref).is_file(), ref
    arm = assets.vendor_gripper("franka-panda-arm")
    root = _parse_urdf(arm)
    assert len(_joints(root, "revolute")) == 7
    share = next(p for p in arm.parents if p.name == "share")
    for ref in _mesh_files(root):
        assert (share / ref[len("package://") :]).is_file(), ref


def test_gripper_names():
    hands = assets.vendor_grippers()
    assert hands == sorted(
        ["allegro-left", "allegro-right", "franka-hand", "pr2-gripper", "robotiq-2f-85"]
    )
    assert set(assets.vendor_grippers(include_arms=True)) == set(hands) | {"franka-panda-arm"}
    with pytest.raises(assets.UnknownAssetError, match="robotiq-2f-85") as info:
        assets.vendor_gripper("robotiq-2f-140")
    assert isinstance(info.value, ISFError)


# ------------------------------------------------------------------ real benchmark objects


@pytest.mark.parametrize(
    ("name", "n_vertices", "extent"), [("bunny", 42_000, 0.15), ("dragon", 47_000, 0.20)]
)
def test_stanford_meshes_unit_normalised_and_scaled(cache, name, n_vertices, extent):
    obj = assets.benchmark_object(name)
    mesh = trimesh.load(obj.path, force="mesh")
    assert abs(len(mesh.vertices) - n_vertices) < 1_000  # the notes: 42k / 47k vertices
    assert mesh.is_watertight
    assert mesh.extents.max() == pytest.approx(1.0, abs=1e-3)  # vendor-normalised
    assert obj.target_extent == extent
    assert mesh.extents.max() * obj.scale == pytest.approx(extent, rel=1e-3)
    assert obj.source == "genesis-world==1.4.5" and "Stanford" in obj.licence
    assert obj.with_extent(0.03).scale * mesh.extents.max() == pytest.approx(0.03, rel=1e-3)


def test_random_objects_all_present_with_urdf_scale(cache):
    names = assets.benchmark_objects("random")
    assert names[0] == "random-000" and names[-1] == "random-499" and len(names) == 500
    objs = [assets.benchmark_object(n) for n in names]
    assert all(o.path.is_file() and o.path.suffix == ".obj" for o in objs)
    assert {o.scale for o in objs} == {0.015}  # the URDFs' <mesh scale>, per the data-sources notes
    mesh = trimesh.load(objs[0].path, force="mesh")
    assert 0.03 < mesh.extents.max() * objs[0].scale < 0.3  # a hand-sized object in metres
    with pytest.raises(assets.UnknownAssetError):
        assets.benchmark_object("random-500")


def test_small_objects_are_hand_sized_in_metres(cache):
    for name in ["duck", "mug", *assets.benchmark_objects("robosuite")]:
        obj = assets.benchmark_object(name)
        mesh = trimesh.load(obj.path, force="mesh")
        size = mesh.extents.max() * obj.scale
        assert 0.03 < size < 0.25, (name, size)
        assert obj.target_extent is None
    with pytest.raises(ConfigError):
        assets.benchmark_object("duck").with_extent(0.1)


def test_object_groups_and_unknown_names():
    assert assets.benchmark_objects("stanford") == ["bunny", "dragon"]
    assert assets.benchmark_objects("robosuite") == [
        "bottle",
        "bread",
        "can",
        "cereal",
        "lemon",
        "milk",
    ]
    assert len(assets.benchmark_objects("all")) == 2 + 2 + 6 + 500
    with pytest.raises(assets.UnknownAssetError, match="group"):
        assets.benchmark_objects("kitchen")
    with pytest.raises(assets.UnknownAssetError, match="ycb:"):
        assets.benchmark_object("teapot")


# ------------------------------------------------------------------ YCB (local folder only)


def test_ycb_found_by_walking_up(monkeypatch):
    repo = Path(__file__).resolve().parents[1]
    ycb = next(
        (p / "shared/data/ycb" for p in repo.parents if (p / "shared/data/ycb").is_dir()), None
    )
    if ycb is None:
        pytest.skip("optional YCB data absent: no shared/data/ycb above the repository")
    monkeypatch.delenv("ISF_YCB_DIR", raising=False)
    monkeypatch.chdir(repo)
    obj = assets.benchmark_object("ycb:mustard_bottle")
    assert obj.path == ycb / "MustardBottle.obj" and obj.name == "ycb:MustardBottle"
    assert obj.scale == 1.0 and "CC BY 4.0" in obj.licence
    assert len(assets.benchmark_objects("ycb")) == len(list(ycb.glob("*.obj")))


def test_ycb_absent_raises(monkeypatch, tmp_path):
    monkeypatch.setenv("ISF_YCB_DIR", str(tmp_path / "missing"))
    with pytest.raises(assets.YCBNotFoundError, match="ISF_YCB_DIR"):
        assets.benchmark_object("ycb:banana")
    monkeypatch.delenv("ISF_YCB_DIR")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(assets.YCBNotFoundError, match="ISF_YCB_DIR"):
        assets.benchmark_objects("ycb")


# ------------------------------------------------------------------ cache behaviour


def test_second_call_uses_cache_without_pip(cache, monkeypatch):
    def no_download(*args, **kwargs):
        raise AssertionError("pip was called although the cache is filled")

    monkeypatch.setattr(assets, "_download_wheel", no_download)
    monkeypatch.setattr(assets.subprocess, "run", no_download)
    for name in assets.vendor_grippers(include_arms=True):
        assert assets.vendor_gripper(name).is_file()
    assert assets.benchmark_object("bunny").path.is_file()
    assert assets.prefetch() == cache


def test_bad_version_gives_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("ISF_CACHE_DIR", str(tmp_path))
    calls = []
    stderr = (
        "WARNING: Location 'file:///opt/x' is ignored\n"
        "ERROR: Could not find a version that satisfies the requirement genesis-world==0.0.0\n"
        "ERROR: No matching distribution found for genesis-world==0.0.0\n"
    )

    def fake_run(cmd, **kwargs):
        calls.append(cmd)
        return subprocess.CompletedProcess(cmd, 1, "", stderr)

    monkeypatch.setattr(assets.subprocess, "run", fake_run)
    bad = dataclasses.replace(assets._GENESIS, version="0.0.0")
    with pytest.raises(
        assets.AssetFetchError, match=r"genesis-world==0\.0\.0.*No matching distribution"
    ) as info:
        assets._package_dir(bad)
    assert isinstance(info.value, ISFError) and "exit code 1" in str(info.value)
    assert {"download", "--no-deps", "--only-binary=:all:", "genesis-world==0.0.0"} <= set(calls[0])
    assert list(tmp_path.iterdir()) == []  # nothing half-made left behind


# ------------------------------------------------------------------ extraction rules (fake wheel)


def _fake_source(tmp_path: Path, monkeypatch, include: tuple[str, ...]) -> assets._Source:
    wheel = tmp_path / "fake-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as zf:
        zf.writestr(
            "pkg/urdf/robot.urdf",
            '<robot name="r"><link name="a"><visual><geometry>'
            '<mesh filename="package://pkg/meshes/a.obj"/></geometry></visual><collision><geometry>'
            '<mesh filename="../meshes/b.stl" scale="0.001 0.001 0.001"/></geometry></collision>'
            "</link></robot>",
        )
        zf.writestr("pkg/meshes/a.obj", "mtllib a.mtl\nv 0 0 0\n")
        zf.writestr("pkg/meshes/a.mtl", "newmtl m\nmap_Kd tex.png\n")
        zf.writestr("pkg/meshes/tex.png", b"png")
        zf.writestr("pkg/meshes/b.stl", b"solid")
        zf.writestr("pkg/meshes/unused.stl", b"solid")
    monkeypatch.setenv("ISF_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(assets, "_download_wheel", lambda src, dest: Path(shutil.copy(wheel, dest)))
    return assets._Source("fake", "1.0", include, "test")


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def test_extracts_urdf_with_referenced_meshes_only(monkeypatch, tmp_path):
    src = _fake_source(tmp_path, monkeypatch, (r"pkg/urdf/robot\.urdf",))
    folder = assets._package_dir(src)
    assert folder == tmp_path / "cache" / "fake-1.0"
    assert _files(folder) == {
        "pkg/urdf/robot.urdf",
        "pkg/meshes/a.obj",
        "pkg/meshes/a.mtl",
        "pkg/meshes/tex.png",
        "pkg/meshes/b.stl",
        ".isf-fetch.json",
    }
    # a changed member selection for the same version replaces the cached folder
    wider = dataclasses.replace(src, include=(r"pkg/meshes/unused\.stl",))
    assert _files(assets._package_dir(wider)) == {"pkg/meshes/unused.stl", ".isf-fetch.json"}
    assert [p.name for p in (tmp_path / "cache").iterdir()] == ["fake-1.0"]


def test_interrupted_extraction_leaves_no_cache(monkeypatch, tmp_path):
    src = _fake_source(tmp_path, monkeypatch, (r"pkg/.*",))
    real_copy = shutil.copyfileobj
    n_calls = []

    def dying_copy(fsrc, fdst, *args):
        n_calls.append(1)
        if len(n_calls) == 3:
            raise KeyboardInterrupt
        return real_copy(fsrc, fdst, *args)

    monkeypatch.setattr(assets.shutil, "copyfileobj", dying_copy)
    with pytest.raises(KeyboardInterrupt):
        assets._package_dir(src)
    assert list((tmp_path / "cache").iterdir()) == []
    monkeypatch.setattr(assets.shutil, "copyfileobj", real_copy)
    assert len(_files(assets._package_dir(src))) == 7
