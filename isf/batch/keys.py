"""The key of a batch task: a hash of everything its result depends on.

The key is the SHA-256 of the task's fields (:meth:`BatchTask.to_dict`), the SHA-256 of the
files it reads (the object or scene file, the gripper's URDF, a camera pose file) and the isf
version, as canonical JSON; its first 16 hex digits name the task's output files. A hashed
file counts by its name and bytes, not its folder, so a manifest moved elsewhere with its files
keeps its keys. Changing a parameter, editing a file or upgrading isf makes a new task. Meshes
a URDF refers to are not hashed: a mesh edited in place under the same URDF keeps the key
(rename the URDF, or change a field, to plan again).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import NamedTuple

from .manifest import BatchTask

__all__ = ["KEY_LENGTH", "KeyedTask", "file_sha256", "key_tasks"]

KEY_LENGTH = 16
"""Hex digits of a task key (64 bits: a collision among a million tasks has odds ~1e-8)."""


class KeyedTask(NamedTuple):
    """A task with its key and the SHA-256 of the files it reads (None: not a file, or
    unreadable: the task then fails when it runs, with the reader's error)."""

    key: str
    task: BatchTask
    gripper_sha256: str | None
    object_sha256: str | None


def file_sha256(path: str | Path) -> str | None:
    """SHA-256 (hex) of a file's bytes; of a folder, of its ``*.urdf`` files in name order;
    None when there is no such readable file."""
    path = Path(path)
    try:
        files = sorted(path.glob("*.urdf")) if path.is_dir() else [path]
        if not files:
            return None
        digest = hashlib.sha256()
        for file in files:
            with open(file, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    digest.update(block)
        return digest.hexdigest()
    except OSError:
        return None


def key_tasks(tasks: list[BatchTask]) -> list[KeyedTask]:
    """Each task with its key (files hashed once each, however many tasks read them)."""
    from .. import __version__
    from ..gripper.bundled import bundled_grippers

    bundled = bundled_grippers()
    hashes: dict[str, str | None] = {}

    def sha(source: str | None) -> str | None:
        if source is None or source.startswith(("shape:", "asset:")):
            return None
        if source not in hashes:
            hashes[source] = file_sha256(bundled.get(source, source))
        return hashes[source]

    keyed = []
    for task in tasks:
        target = task.object if task.object is not None else task.scene
        pose = task.camera_pose if task.camera_pose and "," not in task.camera_pose else None
        fields = task.to_dict()
        for name in ("gripper", "object", "scene", "camera_pose"):  # a hashed file by its name
            if fields[name] is not None and sha(fields[name]) is not None:
                fields[name] = Path(fields[name]).name
        identity = {"isf": __version__, "task": fields, "gripper_sha256": sha(task.gripper),
                    "object_sha256": sha(target), "camera_pose_sha256": sha(pose)}
        text = json.dumps(identity, sort_keys=True, separators=(",", ":"), default=str)
        key = hashlib.sha256(text.encode("utf-8")).hexdigest()[:KEY_LENGTH]
        keyed.append(KeyedTask(key, task, identity["gripper_sha256"], identity["object_sha256"]))
    return keyed
