"""The dataset a batch writes: its Parquet schemas, the rows of a plan, and reading it back.

One row per grasp (:data:`GRASP_SCHEMA`) in ``DIR/grasps/<key>.parquet``, one per task, so
``pandas.read_parquet(DIR / "grasps")`` reads them all; one row per task (:data:`TASK_SCHEMA`)
in ``DIR/tasks.parquet``; each task's plan file in ``DIR/plans/<key>.json``. Grasp rows are
read from the plan file's content (:func:`isf.planning.plan_json.plan_to_dict`), the one source
of truth for what a grasp is; frames and units are the plan file's (docs/json-schema.md):
metres, radians, ``T_object_gripper`` the gripper frame (URDF root link) in the object frame.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NamedTuple

import pyarrow as pa

__all__ = ["BatchDataset", "GRASP_SCHEMA", "TASK_SCHEMA", "grasp_table", "load_dataset",
           "task_table"]

_POSE = pa.list_(pa.float64(), 16)

GRASP_SCHEMA = pa.schema([
    pa.field("task_key", pa.string(), nullable=False),
    pa.field("object", pa.string(), nullable=False),
    pa.field("gripper", pa.string(), nullable=False),
    pa.field("sampler", pa.string(), nullable=False),
    pa.field("seed", pa.int64()),
    pa.field("rank", pa.int32(), nullable=False),
    pa.field("T_object_gripper", _POSE, nullable=False),
    pa.field("T_object_tcp", _POSE),
    pa.field("position", pa.list_(pa.float64(), 3)),
    pa.field("quaternion_xyzw", pa.list_(pa.float64(), 4)),
    pa.field("T_object_pregrasp_tcp", _POSE),
    pa.field("joints", pa.map_(pa.string(), pa.float64()), nullable=False),
    pa.field("joint_state", pa.map_(pa.string(), pa.float64())),
    pa.field("mean_distance", pa.float64()),
    pa.field("normal_misalignment", pa.float64()),
    pa.field("fit_error", pa.float64()),
    pa.field("n_pairs", pa.int64()),
    pa.field("surface_contact", pa.map_(pa.string(), pa.float64())),
    pa.field("status", pa.string()),
    pa.field("iterations", pa.int64()),
    pa.field("collision_free", pa.bool_(), nullable=False),
    pa.field("clearance", pa.float64()),
    pa.field("penetration", pa.float64()),
    pa.field("valid", pa.bool_(), nullable=False),
    pa.field("repaired", pa.bool_()),
    pa.field("centred", pa.bool_()),
    pa.field("epsilon", pa.float64()),
    pa.field("force_closure", pa.bool_()),
    pa.field("gravity_margin", pa.map_(pa.string(), pa.float64())),
    pa.field("min_margin", pa.float64()),
    pa.field("com_offset", pa.float64()),
    pa.field("squeeze_imbalance", pa.float64()),
    pa.field("closing_obstructed_by", pa.list_(pa.string())),
    pa.field("duplicate_of", pa.int32()),
    pa.field("sample_index", pa.int64()),
    pa.field("plan_time", pa.float64()),
    pa.field("fit_time", pa.float64()),
    pa.field("collision_time", pa.float64()),
])
"""One row per grasp.

Poses are 4x4 matrices row by row, 16 floats (metres), in the object (or scene) frame:
``T_object_gripper`` the gripper frame (URDF root link), ``T_object_tcp`` the tool centre
point (the plan file's ``tcp``), ``T_object_pregrasp_tcp`` the TCP backed off along the
approach axis; ``position`` (metres) and ``quaternion_xyzw`` (unit, w >= 0) are the TCP's;
``joints`` the actuated joints, ``joint_state`` every joint of the URDF (radians or metres);
``mean_distance``, ``normal_misalignment`` (radians) and ``fit_error`` are ISF's errors;
the grasp quality of a valid grasp of a plan ranked by quality (the plan file's ``quality``
record and ``closing_obstructed_by``, docs/quality.md): ``epsilon`` (Ferrari-Canny),
``force_closure``, ``gravity_margin`` (per gravity direction ``+x`` ... ``-z``, object frame:
the largest load resisted over the object's weight), ``min_margin``, ``com_offset`` (metres,
contacts' centroid to the centre of mass), ``squeeze_imbalance`` and
``closing_obstructed_by`` (null for other grasps, with ``rank: fit``, and in files written
before these columns existed);
``duplicate_of`` the rank of the better grasp this one repeats; ``plan_time``, ``fit_time``
and ``collision_time`` the seconds of the whole plan (every row of a task repeats them).
Null where the plan file lacks the field."""

TASK_SCHEMA = pa.schema([
    pa.field("task_key", pa.string(), nullable=False),
    pa.field("status", pa.string(), nullable=False),
    pa.field("error", pa.string()),
    pa.field("error_kind", pa.string()),
    pa.field("object", pa.string(), nullable=False),
    pa.field("gripper", pa.string(), nullable=False),
    pa.field("sampler", pa.string(), nullable=False),
    pa.field("seed", pa.int64()),
    pa.field("samples", pa.int64()),
    pa.field("grasps", pa.int64()),
    pa.field("valid", pa.int64()),
    pa.field("collision_free", pa.int64()),
    pa.field("attempts", pa.int64()),
    pa.field("load_time", pa.float64()),
    pa.field("warm_time", pa.float64()),
    pa.field("plan_time", pa.float64()),
    pa.field("task_time", pa.float64()),
    pa.field("finished_at", pa.string()),
    pa.field("plan_file", pa.string()),
    pa.field("grasps_file", pa.string()),
    pa.field("warnings", pa.list_(pa.string())),
    pa.field("task", pa.string(), nullable=False),
    pa.field("provenance", pa.string()),
])
"""One row per task of the manifest.

``status`` is ``done``, ``failed`` or ``pending`` (not
run yet: an interrupted batch); ``error_kind`` ``input``, ``internal`` or ``worker`` (see
:class:`isf.batch.TaskOutcome`); ``attempts`` counts the runs of the task over every
invocation on the folder; times in seconds; ``plan_file`` and ``grasps_file`` are relative to
the folder; ``task`` is the manifest's fields as JSON, with the SHA-256 of the files read;
``provenance`` as JSON: ``worker``, where it ran (host, pid, python, isf version, start time,
the process's peak memory in MB),
and ``plan``, the plan file's ``provenance`` (files and their SHA-256, parameters)."""


def _pose(value) -> list[float] | None:
    return None if value is None else [float(v) for row in value for v in row]


def _floats(value) -> list[float] | None:
    return None if value is None else [float(v) for v in value]


def _mapping(value) -> list[tuple[str, float]] | None:
    return None if value is None else [(str(k), float(v)) for k, v in value.items()]


def grasp_table(key: str, plan: dict[str, Any]) -> pa.Table:
    """The rows (:data:`GRASP_SCHEMA`) of the grasps of one plan file's content."""
    stats = plan.get("stats") or {}
    rows = []
    for g in plan["grasps"]:
        error = g.get("error") or {}
        tcp = g.get("tcp") or {}  # absent from plan files of schema version 1
        quality = g.get("quality") or {}
        obstructed = g.get("closing_obstructed_by")
        pregrasp = (g.get("pregrasp") or {}).get("tcp") or {}
        rows.append({
            "task_key": key, "object": plan["object"], "gripper": plan["gripper"],
            "sampler": plan["sampler"], "seed": plan.get("seed"), "rank": g["rank"],
            "T_object_gripper": _pose(g["T_object_gripper"]),
            "T_object_tcp": _pose(tcp.get("matrix")),
            "position": _floats(tcp.get("position")),
            "quaternion_xyzw": _floats(tcp.get("quaternion_xyzw")),
            "T_object_pregrasp_tcp": _pose(pregrasp.get("matrix")),
            "joints": _mapping(g["joints"]),
            "joint_state": _mapping(g.get("joint_state")),
            "mean_distance": error.get("mean_distance"),
            "normal_misalignment": error.get("normal_misalignment"),
            "fit_error": error.get("total"), "n_pairs": error.get("n_pairs"),
            "surface_contact": _mapping(error.get("surface_contact")),
            "status": g.get("status"), "iterations": g.get("iterations"),
            "collision_free": g["collision_free"], "clearance": g.get("clearance"),
            "penetration": g.get("penetration"), "valid": g["valid"], "repaired": g.get("repaired"),
            "centred": g.get("centred"),
            "epsilon": quality.get("epsilon"), "force_closure": quality.get("force_closure"),
            "gravity_margin": _mapping(quality.get("gravity_margin")),
            "min_margin": quality.get("min_margin"), "com_offset": quality.get("com_offset"),
            "squeeze_imbalance": quality.get("squeeze_imbalance"),
            "closing_obstructed_by": None if obstructed is None else [str(n) for n in obstructed],
            "duplicate_of": g.get("duplicate_of"), "sample_index": g.get("sample_index"),
            "plan_time": stats.get("total_time"), "fit_time": stats.get("fit_time"),
            "collision_time": stats.get("collision_time"),
        })
    return pa.Table.from_pylist(rows, schema=GRASP_SCHEMA)


def task_table(records: list[dict[str, Any]]) -> pa.Table:
    """The tasks table (:data:`TASK_SCHEMA`) of task records (dicts with its field names;
    ``task`` and ``provenance`` as mappings, written as JSON)."""
    rows = [{**{name: record.get(name) for name in TASK_SCHEMA.names},
             "task": json.dumps(record["task"], sort_keys=True),
             "provenance": None if record.get("provenance") is None
             else json.dumps(record["provenance"], sort_keys=True)} for record in records]
    return pa.Table.from_pylist(rows, schema=TASK_SCHEMA)


class BatchDataset(NamedTuple):
    """A batch's output read back as pandas tables.

    Attributes:
        grasps: one row per grasp (:data:`isf.batch.dataset.GRASP_SCHEMA`) of the finished tasks.
        tasks: one row per task (:data:`isf.batch.dataset.TASK_SCHEMA`).
        folder: the batch's folder (``plans/<key>.json`` are the plan files).
    """

    grasps: Any
    tasks: Any
    folder: Path


def load_dataset(folder: str | Path, *, done_only: bool = True) -> BatchDataset:
    """Read the dataset a batch wrote into ``folder``.

    Args:
        folder: the ``--out`` folder of ``isf batch``.
        done_only: keep only the grasps of tasks the tasks table records as done (a task
            finished by an interrupted batch before it was recorded is left out).

    Raises:
        InvalidInputError: ``folder`` holds no batch output (no ``tasks.parquet``).
    """
    import pandas as pd
    import pyarrow.dataset as ds

    from ..exceptions import InvalidInputError

    folder = Path(folder)
    if not (folder / "tasks.parquet").is_file():
        raise InvalidInputError(f"{folder} holds no batch output (no tasks.parquet): pass the "
                                "--out folder of isf batch")
    tasks = pd.read_parquet(folder / "tasks.parquet")
    files = sorted((folder / "grasps").glob("*.parquet"))
    if done_only:
        done = set(tasks.loc[tasks["status"] == "done", "task_key"])
        files = [f for f in files if f.stem in done]
    table = ds.dataset([str(f) for f in files], schema=GRASP_SCHEMA, format="parquet").to_table() \
        if files else GRASP_SCHEMA.empty_table()
    return BatchDataset(table.to_pandas(), tasks, folder)
