"""The command line end to end: exit codes, JSON schema, one-line errors, no partial output."""

import dataclasses
import json
import subprocess
import sys

import jsonschema
import numpy as np
import pytest

import isf
from isf.planning.plan_json import SCHEMA_PATH


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "isf", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def schema():
    return json.loads(SCHEMA_PATH.read_text())


def test_plan_writes_valid_json(tmp_path, schema):
    out = tmp_path / "grasps.json"
    proc = run("plan", "--gripper", "paper-parallel", "--object", "shape:cylinder", "--samples", "6",
               "--seed", "1", "--top", "4", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert str(out) in proc.stdout and "collision-free" in proc.stdout
    data = json.loads(out.read_text())
    jsonschema.validate(data, schema)
    assert data["units"] == "m" and data["gripper"] == "paper-parallel"
    assert len(data["grasps"]) == 4 and data["stats"]["samples"] == 6
    assert [g["rank"] for g in data["grasps"]] == [1, 2, 3, 4]
    assert set(data["grasps"][0]["joints"]) == {"left_finger_joint"}
    assert data["stats"]["workers"] == 1


def test_plan_with_worker_threads(tmp_path, schema):
    out = tmp_path / "grasps.json"
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "6", "--workers", "2",
               "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    jsonschema.validate(data, schema)
    assert data["stats"]["workers"] == 2 and len(data["grasps"]) == 6


@pytest.mark.parametrize("gripper, seed, flags, key, keyword, config", [
    ("three-finger", 3, ["--repair", "max_rows=6", "--repair", "iterations=3"], "repair",
     "repair_collisions", isf.RepairConfig(max_rows=6, iterations=3)),
    ("paper-parallel", 2, ["--fit", "tolerance=0.016", "--fit", "max_ipfo_iterations=4"], "config",
     "config", isf.FitConfig(tolerance=0.016, max_ipfo_iterations=4)),
])
def test_plan_with_parameters_gives_the_library_plan(tmp_path, schema, gripper, seed, flags, key,
                                                     keyword, config):
    out = tmp_path / "grasps.json"
    proc = run("plan", "-g", gripper, "-o", "shape:cylinder", "-n", "4", "--seed", str(seed), *flags,
               "--out", str(out), "--quiet")
    assert proc.returncode in (0, 1), proc.stderr
    data = json.loads(out.read_text())
    jsonschema.validate(data, schema)
    assert data[key] == json.loads(json.dumps(dataclasses.asdict(config)))
    cylinder = isf.open_object("shape:cylinder")
    result = isf.plan(gripper, cylinder, samples=4, seed=seed, **{keyword: config})
    poses = [np.asarray(g.T_object_gripper).tolist() for g in result.grasps]
    assert [g["T_object_gripper"] for g in data["grasps"]] == poses
    default = isf.plan(gripper, cylinder, samples=4, seed=seed)  # the parameters matter here
    assert [np.asarray(g.T_object_gripper).tolist() for g in default.grasps] != poses


def test_plan_without_repair(tmp_path):
    out = tmp_path / "grasps.json"
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2", "--no-repair",
               "--out", str(out), "--quiet")
    assert proc.returncode in (0, 1), proc.stderr
    assert json.loads(out.read_text())["repair"] is None
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-n", "2", "--no-repair",
               "--repair", "max_rows=6", "--out", str(tmp_path / "none.json"))
    assert proc.returncode == 2 and "exclude each other" in proc.stderr
    assert not (tmp_path / "none.json").exists()


def test_plan_with_table_and_units(tmp_path, schema):
    mesh = tmp_path / "box_mm.stl"
    import trimesh

    trimesh.creation.box(extents=[50, 20, 15]).export(mesh)  # millimetres
    out = tmp_path / "g.json"
    proc = run("plan", "-g", "paper-parallel", "-o", str(mesh), "--units", "mm", "--table", "-0.0075",
               "-n", "4", "--out", str(out), "--quiet")
    assert proc.returncode in (0, 1), proc.stderr
    jsonschema.validate(json.loads(out.read_text()), schema)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--object", "missing.stl"], "missing.stl"),
        (["--object", "garbage.stl"], "garbage.stl"),
        (["--gripper", "no-such-gripper"], "no-such-gripper"),
        (["--sampler", "no-such-sampler"], "no-such-sampler"),
        (["--object", "shape:no-such-shape"], "no-such-shape"),
        (["--object", "box_mm.stl"], "units"),
        (["--workers", "0"], "--workers"),
        (["--samples", "0"], "--samples must be >= 1"),
        (["--workers", "2", "--batch-size", "2"], "--workers"),
        (["--repair", "max_rowz=6"], "max_rowz"),
        (["--repair", "max_rows=six"], "RepairConfig.max_rows takes an integer"),
        (["--repair", "max_rows"], "--repair 'max_rows' must look like NAME=VALUE"),
        (["--fit", "tolerence=0.016"], "tolerence"),
        (["--fit", "tolerance=loose"], "FitConfig.tolerance takes a number"),
        (["--fit", "levels=0"], "FitConfig.levels must be an integer >= 1"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, args, message):
    (tmp_path / "garbage.stl").write_bytes(b"\x00\x01 definitely not a mesh \xff" * 10)
    import trimesh

    trimesh.creation.box(extents=[50, 20, 15]).export(tmp_path / "box_mm.stl")
    base = {"--gripper": "paper-parallel", "--object": "shape:cylinder", "--sampler": "regret",
            "--samples": "2"}
    base.update(dict(zip(args[::2], args[1::2])))
    flat = [x for kv in base.items() for x in kv]
    proc = run("plan", *flat, "--out", "out.json", cwd=tmp_path)
    assert_one_line_error(proc, message)
    assert not (tmp_path / "out.json").exists()


def assert_one_line_error(proc, message):
    """The command failed with exit code 2 and one line on stderr that names ``message``."""
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("isf: error:"), proc.stderr
    assert message in lines[0]
    assert "Traceback" not in proc.stderr


def test_plan_of_several_objects_gives_each_library_plan(tmp_path, schema):
    specs = ["shape:cylinder", "shape:box"]
    proc = run("plan", "-g", "paper-parallel", "-o", specs[0], "-o", specs[1], "-n", "4",
               "--seed", "1", "--out-dir", str(tmp_path / "plans"), "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "plans").iterdir()) == ["box.json", "cylinder.json"]
    for spec in specs:
        data = json.loads((tmp_path / "plans" / f"{spec.removeprefix('shape:')}.json").read_text())
        jsonschema.validate(data, schema)
        assert data["object"] == spec
        result = isf.plan("paper-parallel", isf.open_object(spec), samples=4, seed=1)
        assert [g["T_object_gripper"] for g in data["grasps"]] == [
            np.asarray(g.T_object_gripper).tolist() for g in result.grasps]


def test_plan_of_several_objects_releases_each_object_after_its_plan(tmp_path, monkeypatch):
    import gc
    import weakref

    import isf.object.specs
    import isf.planning.planner
    from isf.cli import main

    loaded, alive_at_plan = [], []
    open_object, plan = isf.object.specs.open_object, isf.planning.planner.plan

    def recording_open(*args, **kwargs):
        obj = open_object(*args, **kwargs)
        loaded.append(weakref.ref(obj))
        return obj

    def recording_plan(*args, **kwargs):
        gc.collect()
        alive_at_plan.append(sum(ref() is not None for ref in loaded))
        return plan(*args, **kwargs)

    monkeypatch.setattr(isf.object.specs, "open_object", recording_open)
    monkeypatch.setattr(isf.planning.planner, "plan", recording_plan)
    specs = ["shape:cylinder", "shape:box", "shape:sphere"]
    argv = ["plan", "-g", "paper-parallel", "-n", "2", "--out-dir", str(tmp_path), "--quiet"]
    assert main(argv + [flag for spec in specs for flag in ("-o", spec)]) in (0, 1)
    assert len(loaded) == 3 and alive_at_plan == [1, 1, 1]  # each read in turn, then dropped
    assert len(list(tmp_path.iterdir())) == 3


def test_plan_of_several_objects_stops_at_an_unreadable_one_with_the_files_before_complete(
        tmp_path, schema):
    (tmp_path / "garbage.stl").write_bytes(b"\x00\x01 definitely not a mesh \xff" * 10)
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", "-o", "garbage.stl",
               "-o", "shape:box", "-n", "2", "--out-dir", "plans", "--quiet", cwd=tmp_path)
    assert_one_line_error(proc, "garbage.stl: ")
    assert "the 1 object(s) before it are planned" in proc.stderr
    assert [p.name for p in (tmp_path / "plans").iterdir()] == ["cylinder.json"]
    jsonschema.validate(json.loads((tmp_path / "plans" / "cylinder.json").read_text()), schema)


@pytest.mark.parametrize(
    "args, message",
    [
        (["-o", "shape:box", "--out", "out.json"], "2 objects need --out-dir DIR"),
        (["-o", "sub/cylinder.stl", "--out-dir", "plans"], "would both write plans/cylinder.json"),
        (["-o", "missing.stl", "--out-dir", "plans"], "missing.stl"),
        (["-o", "shape:no-such-shape", "--out-dir", "plans"], "no-such-shape"),
        (["--out", "out.json", "--out-dir", "plans"], "--out and --out-dir exclude each other"),
        (["--out-dir", "no-such-folder/plans"], "no-such-folder/plans"),
    ],
)
def test_bad_output_for_several_objects_is_one_line_exit_2_and_no_file(tmp_path, args, message):
    proc = run("plan", "-g", "paper-parallel", "-o", "shape:cylinder", *args, "-n", "2",
               cwd=tmp_path)
    assert_one_line_error(proc, message)
    assert list(tmp_path.iterdir()) == []


def test_listing_commands():
    proc = run("grippers")
    assert proc.returncode == 0
    assert {"paper-parallel", "flat-parallel", "three-finger"} <= {l.split()[0] for l in proc.stdout.splitlines()}
    proc = run("samplers")
    assert proc.returncode == 0
    assert {"regret", "uniform", "normal"} <= {l.split()[0] for l in proc.stdout.splitlines()}


def test_inspect(tmp_path):
    proc = run("inspect", "three-finger")
    assert proc.returncode == 0, proc.stdout
    for name in ("f0_pad", "f1_pad", "f2_pad", "f0_proximal_joint"):
        assert name in proc.stdout
    broken = tmp_path / "broken.urdf"
    broken.write_text('<robot name="b" xmlns:isf="urn:isf:gripper:1"><link name="a"/>'
                      '<isf:contact name="c" link="nowhere"/></robot>')
    proc = run("inspect", str(broken))
    assert proc.returncode == 1
    assert "nowhere" in proc.stdout


def test_tag_writes_a_loadable_copy_of_a_stock_urdf(tmp_path):
    from isf.assets import vendor_gripper

    stock = vendor_gripper("franka-hand")
    before = stock.read_bytes()
    out = tmp_path / "franka_tagged.urdf"
    proc = run("tag", str(stock), "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "left_finger_pad" in proc.stdout and "OK" in proc.stdout
    assert stock.read_bytes() == before
    proc = run("inspect", str(out))
    assert proc.returncode == 0 and "right_finger_pad" in proc.stdout
    proc = run("tag", str(stock), "--out", str(tmp_path / "x.urdf"), "--approach", "1,2")
    assert proc.returncode == 2 and proc.stderr.startswith("isf: error:")


def test_sampler_parameters_from_the_command_line_give_the_library_plan(tmp_path):
    out = tmp_path / "grasps.json"
    proc = run("plan", "--gripper", "paper-parallel", "--object", "shape:cylinder", "--samples", "5",
               "--sampler-param", "orientation=random", "--sampler-param", "n_clusters=3",
               "--out", str(out))
    assert proc.returncode in (0, 1), proc.stderr
    library = isf.plan("paper-parallel", isf.open_object("shape:cylinder"), samples=5,
                       sampler=isf.get_sampler("regret", orientation="random", n_clusters=3))
    data = json.loads(out.read_text())
    np.testing.assert_allclose([g["T_object_gripper"] for g in data["grasps"]],
                               [g.T_object_gripper for g in library.grasps], atol=1e-12)
    assert {g["sampler"].get("cluster", g["sampler"].get("start")) for g in data["grasps"]} \
        <= {0, 1, 2, "centre_of_mass"}


@pytest.mark.parametrize("param, message", [
    ("n_clusters=0", "n_clusters must be an integer >= 1"),
    ("orientation=sideways", "orientation must be one of"),
    ("clusters=3", "accepted parameters"),
    ("gamma", "must look like NAME=VALUE"),
])
def test_bad_sampler_parameters_exit_2_in_one_line(tmp_path, param, message):
    out = tmp_path / "grasps.json"
    proc = run("plan", "--gripper", "paper-parallel", "--object", "shape:cylinder",
               "--sampler-param", param, "--out", str(out))
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
