"""The output folder of a batch: each task's files written atomically, then recorded.

A finished task's files are renamed into place (``grasps/<key>.parquet``, then
``plans/<key>.json``), and only then is the task recorded: a line appended to
``journal.jsonl`` and flushed to disk. A task is finished when its last record says ``done``
and its files are there; a rerun skips exactly those. A task killed before its record is
written is run again, and its files replaced, never added to: each task has one file of rows,
named by its key. ``tasks.parquet`` (the tasks table) is written from the journal at the end
of each run. Files of tasks no longer in the manifest (a changed parameter gives a new key)
are moved into ``superseded/`` so that the folder's dataset is the manifest's. One batch
writes a folder at a time: a second one is refused while the first holds the folder's lock
(``fcntl.flock`` on ``.lock``, released by the system when its holder exits, even by SIGKILL).
"""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from ..exceptions import InvalidInputError, OutputFileError
from ..output_files import write_atomically
from .dataset import grasp_table, task_table
from .keys import KeyedTask
from .worker import TaskOutcome

try:
    import fcntl
except ImportError:  # not POSIX: the folder is not locked
    fcntl = None

__all__ = ["BatchFolder"]


class BatchFolder:
    """The ``--out`` folder of a batch: its records and its files; a context manager that
    holds the folder's lock.

    Raises:
        OutputFileError: the folder cannot be made or is not writable.
        InvalidInputError: another batch is writing the folder (on entering).
    """

    def __init__(self, root: str | Path):
        self.root = Path(root)
        try:
            for sub in ("grasps", "plans"):
                (self.root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputFileError(f"cannot make batch folder {self.root}: {err.strerror or err}: "
                                  "pass another --out", path=self.root) from None
        self.journal = self.root / "journal.jsonl"
        self.records: dict[str, dict[str, Any]] = {}
        self._lock = None

    def __enter__(self) -> BatchFolder:
        if fcntl is not None:
            self._lock = open(self.root / ".lock", "ab")  # closed on exit, releasing the lock
            try:
                fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                self._lock.close()
                raise InvalidInputError(f"another isf batch is writing {self.root}: wait for it "
                                        "to end, or pass another --out") from None
            except OSError:  # a file system without locks
                pass
        self.records = self._read_journal()
        return self

    def __exit__(self, *exc) -> None:
        if self._lock is not None:
            self._lock.close()  # releases the lock
            self._lock = None

    def _read_journal(self) -> dict[str, dict[str, Any]]:
        """The last record of each task key (a line cut short by a kill is skipped)."""
        records: dict[str, dict[str, Any]] = {}
        if self.journal.is_file():
            for line in self.journal.read_text(encoding="utf-8").splitlines():
                try:
                    record = json.loads(line)
                    records[record["task_key"]] = record
                except (ValueError, KeyError, TypeError):
                    continue
        return records

    def is_finished(self, key: str) -> bool:
        """True when the task is recorded done and its files are in place."""
        record = self.records.get(key)
        return (record is not None and record["status"] == "done"
                and (self.root / record["grasps_file"]).is_file()
                and (self.root / record["plan_file"]).is_file())

    def save(self, keyed: KeyedTask, outcome: TaskOutcome) -> dict[str, Any]:
        """Write a task's files atomically, then record it; returns its record."""
        key = keyed.key
        record = _base_record(keyed, outcome)
        record["attempts"] = (self.records.get(key) or {}).get("attempts", 0) + 1
        if outcome.status == "done":
            plan = outcome.plan
            table = grasp_table(key, plan)
            buffer = io.BytesIO()
            pq.write_table(table, buffer)
            grasps_file, plan_file = f"grasps/{key}.parquet", f"plans/{key}.json"
            write_atomically(self.root / grasps_file, buffer.getvalue(), "grasps file")
            write_atomically(self.root / plan_file, outcome.plan_text.encode("utf-8"), "plan file")
            stats = plan.get("stats") or {}
            record["provenance"]["plan"] = plan.get("provenance")
            record.update(grasps=table.num_rows, valid=stats.get("valid"),
                          collision_free=stats.get("collision_free"),
                          plan_file=plan_file, grasps_file=grasps_file)
        self._append(record)
        self.records[key] = record
        return record

    def _append(self, record: dict[str, Any]) -> None:
        line = json.dumps(record, sort_keys=True) + "\n"
        try:
            with open(self.journal, "ab") as f:
                if f.tell() and not _ends_with_newline(self.journal):
                    f.write(b"\n")  # the last line was cut short by a kill
                f.write(line.encode("utf-8"))
                f.flush()
                os.fsync(f.fileno())
        except OSError as err:
            raise OutputFileError(f"cannot record a task in {self.journal}: "
                                  f"{err.strerror or err}: check the folder's free space",
                                  path=self.journal) from None

    def retire_others(self, keys: set[str]) -> int:
        """Move the files of tasks whose key is not in ``keys`` into ``superseded/``; returns
        how many tasks' files moved."""
        moved = set()
        for sub, suffix in (("grasps", ".parquet"), ("plans", ".json")):
            for path in (self.root / sub).glob(f"*{suffix}"):
                if path.stem not in keys:
                    target = self.root / "superseded" / sub
                    target.mkdir(parents=True, exist_ok=True)
                    path.replace(target / path.name)
                    moved.add(path.stem)
        return len(moved)

    def write_tasks_table(self, keyed_tasks: list[KeyedTask]) -> Path:
        """Write ``tasks.parquet``: the last record of each task of the manifest, ``pending``
        for those never run."""
        rows = [self.records.get(k.key) or {**_base_record(k, None), "status": "pending"}
                for k in keyed_tasks]
        buffer = io.BytesIO()
        pq.write_table(task_table(rows), buffer)
        return write_atomically(self.root / "tasks.parquet", buffer.getvalue(), "tasks table")


def _ends_with_newline(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) == b"\n"


def _base_record(keyed: KeyedTask, outcome: TaskOutcome | None) -> dict[str, Any]:
    """A task's record without its files: what the manifest says and how it went."""
    task = keyed.task
    record: dict[str, Any] = {
        "task_key": keyed.key, "object": task.target, "gripper": task.gripper,
        "sampler": task.sampler, "seed": task.seed, "samples": task.samples,
        "task": {**task.to_dict(), "gripper_sha256": keyed.gripper_sha256,
                 "object_sha256": keyed.object_sha256},
        "attempts": 0, "grasps": 0,
    }
    if outcome is not None:
        record.update(
            status=outcome.status, error=outcome.error, error_kind=outcome.error_kind,
            load_time=outcome.load_time, warm_time=outcome.warm_time,
            plan_time=outcome.plan_time, task_time=outcome.task_time,
            warnings=outcome.warnings, provenance={"worker": outcome.provenance, "plan": None},
            finished_at=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    return record
