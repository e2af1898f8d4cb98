"""``isf batch``: failing tasks recorded while the others finish, exactly-once resumption after
SIGKILL, keys that follow the inputs, the Parquet schema, and Dask processes agreeing with a
plain sequential run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from isf.batch import GRASP_SCHEMA, SYNCHRONOUS, TASK_SCHEMA, load_dataset, run_batch
from isf.cli import main

SAMPLES = 2


def _write_manifest(folder, text: str):
    path = folder / "manifest.yaml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def broken_batch(tmp_path_factory):
    """Four tasks, one reading a file that is no mesh, one a gripper that does not exist, run
    by the command line in this process; (folder, exit code, stdout)."""
    folder = tmp_path_factory.mktemp("broken")
    (folder / "not-a-mesh.stl").write_text("solid nothing\nthis is no triangle\n")
    manifest = _write_manifest(folder, f"""
defaults: {{samples: {SAMPLES}}}
cross:
  object: [shape:cylinder, shape:box, not-a-mesh.stl]
  gripper: paper-parallel
tasks:
  - {{object: shape:cylinder, gripper: no-such-gripper.urdf}}
""")
    out = folder / "out"
    code = main(["batch", str(manifest), "--out", str(out), "--scheduler", SYNCHRONOUS, "--quiet"])
    return out, code


def test_failing_tasks_are_recorded_and_the_others_finish(broken_batch):
    out, code = broken_batch
    assert code == 1  # some task failed
    tasks = pd.read_parquet(out / "tasks.parquet").set_index("object")
    assert len(tasks) == 4
    assert tasks.loc["shape:box", "status"] == "done"
    bad = tasks.loc[str(out.parent / "not-a-mesh.stl")]
    assert bad["status"] == "failed" and bad["error_kind"] == "input"
    assert bad["error"].startswith("ObjectLoadError") and "not-a-mesh.stl" in bad["error"]
    missing = tasks[tasks["gripper"].str.endswith("no-such-gripper.urdf")].iloc[0]
    assert missing["status"] == "failed" and "no-such-gripper.urdf" in missing["error"]
    done = tasks[tasks["status"] == "done"]
    assert len(done) == 2 and set(done["grasps"]) == {SAMPLES}
    grasps = pd.read_parquet(out / "grasps")  # plain pandas reads the dataset
    assert sorted(grasps["task_key"].unique()) == sorted(done["task_key"])


def test_the_parquet_files_follow_the_schema_and_the_plan_files(broken_batch):
    out, _ = broken_batch
    files = sorted((out / "grasps").glob("*.parquet"))
    assert files and all(pq.read_schema(f).equals(GRASP_SCHEMA, check_metadata=False) for f in files)
    assert pq.read_schema(out / "tasks.parquet").equals(TASK_SCHEMA, check_metadata=False)
    data = load_dataset(out)
    for key, rows in data.grasps.groupby("task_key"):
        plan = json.loads((out / "plans" / f"{key}.json").read_text())
        assert list(rows["rank"]) == [g["rank"] for g in plan["grasps"]] == [1, 2]
        for (_, row), grasp in zip(rows.iterrows(), plan["grasps"]):
            assert np.array_equal(np.reshape(row["T_object_gripper"], (4, 4)), grasp["T_object_gripper"])
            assert dict(row["joints"]) == grasp["joints"]
            assert row["collision_free"] == grasp["collision_free"]
            if row["T_object_tcp"] is None:  # a plan file without a TCP pose: nothing to check
                continue
            T = np.reshape(row["T_object_tcp"], (4, 4))
            assert np.allclose(T[:3, 3], row["position"])
            R = Rotation.from_quat(row["quaternion_xyzw"]).as_matrix()  # scipy: x, y, z, w
            assert np.allclose(R, T[:3, :3], atol=1e-9)


def test_a_changed_parameter_reruns_only_its_task(tmp_path):
    manifest = _write_manifest(tmp_path, f"""
defaults: {{samples: {SAMPLES}, gripper: paper-parallel}}
tasks:
  - {{object: shape:cylinder, seed: 1}}
  - {{object: shape:box, seed: 1}}
  - {{object: shape:sphere, seed: 1}}
""")
    first = run_batch(manifest, tmp_path / "out", scheduler=SYNCHRONOUS, progress=None)
    assert (first.done, first.skipped) == (3, 0)
    again = run_batch(manifest, tmp_path / "out", scheduler=SYNCHRONOUS, progress=None)
    assert (again.done, again.skipped) == (0, 3)
    manifest.write_text(manifest.read_text().replace("shape:box, seed: 1", "shape:box, seed: 2"))
    ran = []
    changed = run_batch(manifest, tmp_path / "out", scheduler=SYNCHRONOUS, progress=None,
                        on_outcome=ran.append)
    assert (changed.done, changed.skipped, changed.superseded) == (1, 2, 1)
    data = load_dataset(tmp_path / "out")
    box = data.tasks[data.tasks["object"] == "shape:box"]
    assert [o.key for o in ran] == list(box["task_key"]) and json.loads(box["task"].iloc[0])["seed"] == 2
    assert set(data.grasps["seed"]) == {1, 2} and len(data.grasps) == 3 * SAMPLES
    assert len(pd.read_parquet(tmp_path / "out" / "grasps")) == 3 * SAMPLES  # the old rows moved out
    assert len(list((tmp_path / "out" / "superseded" / "grasps").glob("*.parquet"))) == 1


def test_a_batch_killed_half_way_ends_with_every_task_exactly_once(tmp_path):
    objects = ["shape:cylinder", "shape:box", "shape:sphere", "shape:capsule"]
    manifest = _write_manifest(tmp_path, f"""
defaults: {{samples: {SAMPLES}}}
cross:
  object: [{', '.join(objects)}]
  gripper: paper-parallel
  seed: [0, 1]
""")
    out = tmp_path / "out"
    journal = out / "journal.jsonl"
    batch = subprocess.Popen([sys.executable, "-m", "isf", "batch", str(manifest), "--out", str(out),
                              "--scheduler", SYNCHRONOUS, "--quiet"], start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 600
    while batch.poll() is None and time.monotonic() < deadline:
        if journal.is_file() and len(journal.read_text().splitlines()) >= 3:
            os.killpg(batch.pid, signal.SIGKILL)
            break
        time.sleep(0.02)
    batch.wait()
    assert batch.returncode == -signal.SIGKILL, "the batch ended before it could be killed"
    recorded = {json.loads(line)["task_key"] for line in journal.read_text().splitlines()
                if line.endswith("}")}
    assert 3 <= len(recorded) < 8 and not (out / "tasks.parquet").exists()
    summary = run_batch(manifest, out, scheduler=SYNCHRONOUS, progress=None)
    assert summary.ok and summary.skipped == len(recorded) and summary.done == 8 - len(recorded)
    data = load_dataset(out)
    assert len(data.tasks) == 8 and set(data.tasks["status"]) == {"done"}
    assert set(data.tasks["attempts"]) == {1}  # no task recorded twice
    grasps = pd.read_parquet(out / "grasps")
    assert len(grasps) == 8 * SAMPLES and grasps.groupby("task_key").size().eq(SAMPLES).all()
    assert set(grasps["task_key"]) == set(data.tasks["task_key"])
    assert not grasps.duplicated(["task_key", "rank"]).any()


def test_two_dask_processes_plan_what_one_process_plans(tmp_path):
    manifest = _write_manifest(tmp_path, f"""
defaults: {{samples: {SAMPLES}, gripper: paper-parallel}}
cross:
  object: [shape:cylinder, shape:box]
  seed: [3, 4]
""")
    on_dask = run_batch(manifest, tmp_path / "dask", workers=2, progress=None)
    here = run_batch(manifest, tmp_path / "here", scheduler=SYNCHRONOUS, progress=None)
    assert on_dask.ok and here.ok and on_dask.done == here.done == 4
    tasks = load_dataset(tmp_path / "dask").tasks
    pids = {json.loads(p)["worker"]["pid"] for p in tasks["provenance"]}
    assert os.getpid() not in pids  # planned in the worker processes
    a = load_dataset(tmp_path / "dask").grasps.sort_values(["task_key", "rank"])
    b = load_dataset(tmp_path / "here").grasps.sort_values(["task_key", "rank"])
    assert list(a["task_key"]) == list(b["task_key"])
    assert np.allclose(np.stack(a["T_object_gripper"]), np.stack(b["T_object_gripper"]), atol=1e-12)
    joints_a, joints_b = [dict(j) for j in a["joints"]], [dict(j) for j in b["joints"]]
    assert [sorted(j) for j in joints_a] == [sorted(j) for j in joints_b]
    assert np.allclose([[j[k] for k in sorted(j)] for j in joints_a],
                       [[j[k] for k in sorted(j)] for j in joints_b], rtol=0, atol=1e-12)
    assert list(a["collision_free"]) == list(b["collision_free"])


def test_a_bad_manifest_is_a_one_line_usage_error(tmp_path, capsys):
    manifest = _write_manifest(tmp_path, "tasks:\n  - {object: shape:box, gripper: paper-parallel, sample: 3}\n")
    assert main(["batch", str(manifest), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "unknown field(s) ['sample']" in err
    assert not (tmp_path / "out").exists()


def test_the_ranking_and_quality_of_a_task_reach_the_plan_and_the_dataset(tmp_path):
    """Each valid grasp's quality record of the plan file is in the dataset; the same grasps
    ranked for a third of the mass have three times the margins; ``rank: fit`` leaves the
    quality columns empty; a grasp file written without them reads with them empty."""
    manifest = _write_manifest(tmp_path, """
defaults: {samples: 3, gripper: paper-parallel, object: shape:cylinder}
tasks:
  - {seed: 4}
  - {seed: 4, quality: {mass: 0.1, friction: 0.8}}
  - {seed: 4, rank: fit}
""")
    out = tmp_path / "out"
    assert run_batch(manifest, out, scheduler=SYNCHRONOUS, progress=None).done == 3
    data = load_dataset(out)
    by_task = {}
    for key, rows in data.grasps.groupby("task_key"):
        plan = json.loads((out / "plans" / f"{key}.json").read_text())
        by_task[json.dumps(plan["ranking"]["quality"] and
                           [plan["ranking"]["quality"][k] for k in ("mass", "friction")])] = rows
        for (_, row), grasp in zip(rows.iterrows(), plan["grasps"]):
            quality = grasp["quality"]
            if quality is None:
                assert row[["epsilon", "min_margin", "squeeze_imbalance"]].isna().all()
                assert row["force_closure"] is None and row["closing_obstructed_by"] is None
                continue
            assert row["epsilon"] == quality["epsilon"]
            assert row["min_margin"] == quality["min_margin"]
            assert dict(row["gravity_margin"]) == quality["gravity_margin"]
            assert row["com_offset"] == quality["com_offset"]
            assert row["squeeze_imbalance"] == quality["squeeze_imbalance"]
            assert list(row["closing_obstructed_by"]) == grasp["closing_obstructed_by"]
    default, light, fit = by_task["[0.3, 0.5]"], by_task["[0.1, 0.8]"], by_task["null"]
    assert fit["epsilon"].isna().all() and default["epsilon"].notna().any()
    heavy = default.set_index("sample_index")
    for index, row in light.set_index("sample_index").iterrows():
        if row["valid"]:  # friction 0.8 resists more than 0.5: at least three times the margin
            assert row["min_margin"] >= 3 * heavy.loc[index, "min_margin"] * (1 - 1e-9)
    files = sorted((out / "grasps").glob("*.parquet"))
    pq.write_table(pq.read_table(files[0]).drop_columns(["epsilon", "gravity_margin"]), files[0])
    again = load_dataset(out).grasps
    assert len(again) == len(data.grasps) and again["epsilon"].isna().sum() >= 3


def test_a_bad_quality_or_ranking_is_a_one_line_usage_error(tmp_path, capsys):
    for fields, message in (("quality: {mass: 0}", "quality: mass must be a number > 0"),
                            ("quality: {weight: 1}", "quality takes friction, mass"),
                            ("rank: best", "rank 'best' must be one of quality, fit"),
                            ("rank: fit, quality: {mass: 1}", "set rank: quality")):
        manifest = _write_manifest(
            tmp_path, f"tasks:\n  - {{object: shape:box, gripper: paper-parallel, {fields}}}\n")
        assert main(["batch", str(manifest), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err, err
        assert not (tmp_path / "out").exists()


def test_one_batch_writes_a_folder_at_a_time(tmp_path):
    from isf.batch.store import BatchFolder
    from isf.exceptions import InvalidInputError

    manifest = _write_manifest(tmp_path, "tasks:\n  - {object: shape:box, gripper: paper-parallel}\n")
    with BatchFolder(tmp_path / "out"), pytest.raises(InvalidInputError, match="another isf batch"):
        run_batch(manifest, tmp_path / "out", scheduler=SYNCHRONOUS, progress=None)


def test_a_task_whose_worker_dies_is_run_again_then_recorded(tmp_path):
    """The worker's nanny kills it when it passes its memory limit, as a system's out-of-memory
    killer would; loading isf alone passes 400 MB."""
    import logging

    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, memory_limit="400MB",
                               dashboard_address=None, silence_logs=logging.CRITICAL)
    try:
        summary = run_batch({"tasks": [{"object": "shape:box", "gripper": "paper-parallel",
                                        "samples": SAMPLES}]},
                            tmp_path / "out", scheduler=cluster.scheduler_address, retries=1,
                            progress=None)
    finally:
        cluster.close()
    assert not summary.ok and summary.done == 0
    (failure,) = summary.failures
    assert failure.error_kind == "worker" and failure.error.startswith("KilledWorker")
    assert "ran 2 time(s)" in failure.error  # once, then once more (retries=1)
    task = load_dataset(tmp_path / "out").tasks.iloc[0]
    assert task["status"] == "failed" and task["error_kind"] == "worker"


def test_a_csv_and_a_yaml_manifest_of_the_same_tasks_give_the_same_keys(tmp_path):
    from isf.batch import key_tasks, read_manifest

    (tmp_path / "part.stl").write_bytes(b"solid part\nendsolid part\n")  # read by hash only
    csv = tmp_path / "tasks.csv"
    csv.write_text("gripper,object,units,samples,seed,sampler_params,repair\n"
                   "paper-parallel,part.stl,mm,30,0,n_clusters=8 orientation=random,\n"
                   "paper-parallel,part.stl,mm,30,1,n_clusters=8 orientation=random,none\n"
                   "three-finger,shape:box,,,,,\n")
    yaml = _write_manifest(tmp_path, """
tasks:
  - {gripper: paper-parallel, object: part.stl, units: mm, samples: 30, seed: 0,
     sampler_params: {orientation: random, n_clusters: 8}}
  - {gripper: paper-parallel, object: part.stl, units: mm, samples: 30, seed: 1,
     sampler_params: {n_clusters: 8, orientation: random}, repair: null}
  - {gripper: three-finger, object: shape:box}
""")
    from_csv, from_yaml = read_manifest(csv), read_manifest(yaml)
    assert from_csv == from_yaml
    assert from_csv[0].object == str(tmp_path / "part.stl") and from_csv[1].repair is None
    assert from_csv[0].sampler_params == {"n_clusters": 8, "orientation": "random"}
    assert from_csv[2].samples == 60 and from_csv[2].units == "m"  # empty cells: the defaults
    keys = [k.key for k in key_tasks(from_csv)]
    assert keys == [k.key for k in key_tasks(from_yaml)] and len(set(keys)) == 3
    (tmp_path / "part.stl").write_bytes(b"solid other\nendsolid other\n")  # the file changed
    assert [k.key for k in key_tasks(from_csv)][:2] != keys[:2]
