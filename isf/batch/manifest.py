"""The manifest of ``isf batch``: the tasks of a batch, read from YAML or CSV.

A task is one plan: a gripper, an object (or a scene), and the plan's parameters. A YAML
manifest holds ``defaults`` (fields every task starts from), ``cross`` (fields with lists of
values: one task per combination, e.g. objects x grippers x seeds) and ``tasks`` (one mapping
per task); a CSV manifest holds one task per row, one field per column, an empty cell for the
default. Relative file paths are read from the manifest's folder. docs/batch.md describes both.
"""

from __future__ import annotations

import csv
import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import number_or_text
from ..exceptions import ConfigError, InvalidInputError

if TYPE_CHECKING:
    import isf

__all__ = ["BatchTask", "read_manifest", "tasks_from_mapping"]

UNITS = ("m", "cm", "mm")
"""Units an object file's coordinates may be in."""

RANKINGS = ("quality", "fit")
"""The rankings of a task (:func:`isf.plan`'s ``rank``)."""

QUALITY_FIELDS = ("friction", "mass", "grip_force", "cone_edges")
"""The :class:`isf.QualityConfig` fields a task's ``quality`` may set."""

_PARAMETER_MAPS = ("sampler_params", "fit", "repair", "quality")
"""Fields that hold ``{name: value}`` parameters (in CSV: ``KEY=VALUE`` words separated by
spaces)."""


@dataclass(frozen=True)
class BatchTask:
    """One plan of a batch, as the manifest states it. Its fields, named as in the manifest:

    - ``gripper``: a bundled gripper name or a tagged URDF path;
    - ``object``: a mesh or point-cloud path, ``shape:NAME`` or ``asset:NAME``; None with
      ``scene``;
    - ``scene``: instead of ``object``, a depth image or point cloud a camera saw
      (:func:`isf.load_scene`); grasps are then in the scene frame;
    - ``units``: units of the object file's coordinates (``m``, ``cm``, ``mm``); ``scale``:
      extra scale factor of the object;
    - ``samples`` (>= 1), ``sampler`` (:func:`isf.available_samplers`), ``sampler_params``
      (its keyword parameters), ``seed`` (>= 0): as for :func:`isf.plan`;
    - ``fit``: ISF parameters (:class:`isf.FitConfig` fields, as text or values); ``repair``:
      collision-repair parameters (:class:`isf.RepairConfig` fields), None for no repair (the
      paper's Algorithm 3);
    - ``rank``: ``quality`` (the stability-aware ranking) or ``fit`` (the paper's);
      ``quality``: its parameters (``QUALITY_FIELDS`` of :class:`isf.QualityConfig`:
      friction, the object's mass in kg, the grip force in N, the cones' edges);
    - ``table``: a table plane ``z = table`` (metres, object or scene frame), ``"auto"``
      (scenes: found by RANSAC) or None;
    - ``intrinsics`` (``"fx,fy,cx,cy"``, pixels), ``camera_pose`` (``T_scene_camera``: a
      .npy or text file, or 16 numbers), ``depth_scale`` (metres per unit): a scene's camera;
    - ``top``: keep only the best ``top`` grasps (None: all).
    """

    gripper: str
    object: str | None = None
    scene: str | None = None
    units: str = "m"
    scale: float = 1.0
    samples: int = 60
    sampler: str = "regret"
    sampler_params: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    fit: Mapping[str, Any] = field(default_factory=dict)
    repair: Mapping[str, Any] | None = field(default_factory=dict)
    rank: str = "quality"
    quality: Mapping[str, Any] = field(default_factory=dict)
    table: float | str | None = None
    intrinsics: str | None = None
    camera_pose: str | None = None
    depth_scale: float | None = None
    top: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """The task's fields as plain JSON values (parameter maps sorted by key)."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = dict(sorted(value.items())) if isinstance(value, Mapping) else value
        return out

    @property
    def target(self) -> str:
        """The object or scene the task plans on, as the manifest names it."""
        return self.object if self.object is not None else f"scene:{self.scene}"

    def quality_config(self) -> isf.QualityConfig | None:
        """The :class:`isf.QualityConfig` of ``quality`` (its values read as text), or None
        for ``rank: fit``.

        Raises:
            ConfigError: a value :class:`isf.QualityConfig` does not take.
        """
        from ..config import config_from_text
        from ..quality import QualityConfig

        if self.rank == "fit":
            return None
        return config_from_text(QualityConfig, {k: str(v) for k, v in self.quality.items()})


_FIELDS = {f.name: f for f in fields(BatchTask)}


def read_manifest(path: str | Path) -> list[BatchTask]:
    """The tasks of a YAML (``.yaml``, ``.yml``) or CSV (``.csv``) manifest, in its order.

    Raises:
        InvalidInputError: a missing or unreadable file, another suffix, an unknown field, a
            value of the wrong type, a task without gripper or without object and scene.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".csv"):
        raise InvalidInputError(f"manifest {path} must be a .yaml, .yml or .csv file "
                                "(docs/batch.md describes both)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InvalidInputError(f"cannot read manifest {path}: {getattr(err, 'strerror', None) or err}: "
                                "pass a readable YAML or CSV file") from None
    folder = path.resolve().parent
    if suffix == ".csv":
        rows = [{k: v for k, v in row.items() if v not in ("", None)}
                for row in csv.DictReader(text.splitlines())]
        tasks = [_task(row, f"{path.name} row {n}", folder) for n, row in enumerate(rows, start=2)]
    else:
        tasks = tasks_from_mapping(_yaml(text, path), folder, path.name)
    if not tasks:
        raise InvalidInputError(f"manifest {path} lists no task: add tasks or a cross product")
    return tasks


def tasks_from_mapping(manifest: Mapping[str, Any], folder: str | Path = ".",
                       where: str = "manifest") -> list[BatchTask]:
    """The tasks of a manifest given as a mapping (a YAML manifest's content): ``defaults``,
    ``cross`` and ``tasks``; relative paths are read from ``folder``.

    Raises:
        InvalidInputError: as :func:`read_manifest`.
    """
    if not isinstance(manifest, Mapping):
        raise InvalidInputError(f"{where} must be a mapping with 'defaults', 'cross' and/or 'tasks'")
    unknown = set(manifest) - {"defaults", "cross", "tasks"}
    if unknown:
        raise InvalidInputError(f"{where}: unknown section(s) {sorted(unknown)}: use 'defaults', "
                                "'cross' and 'tasks'")
    defaults = manifest.get("defaults") or {}
    cross = manifest.get("cross") or {}
    listed = manifest.get("tasks") or []
    if not isinstance(defaults, Mapping) or not isinstance(cross, Mapping) or not isinstance(listed, list):
        raise InvalidInputError(f"{where}: 'defaults' and 'cross' must be mappings, 'tasks' a list")
    rows = []
    if cross:
        names = list(cross)
        values = [v if isinstance(v, list) else [v] for v in cross.values()]
        rows += [(f"{where} cross product", {**defaults, **dict(zip(names, combo))})
                 for combo in itertools.product(*values)]
    for n, row in enumerate(listed, start=1):
        if not isinstance(row, Mapping):
            raise InvalidInputError(f"{where} task {n} must be a mapping of fields")
        rows.append((f"{where} task {n}", {**defaults, **row}))
    return [_task(row, label, Path(folder)) for label, row in rows]


def _yaml(text: str, path: Path) -> Any:
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise InvalidInputError(f"manifest {path} is not valid YAML: {' '.join(str(err).split())}") from None


def _task(row: Mapping[str, Any], where: str, folder: Path) -> BatchTask:
    """One task from a row of fields (text from CSV, typed values from YAML)."""
    unknown = set(row) - set(_FIELDS)
    if unknown:
        raise InvalidInputError(f"{where}: unknown field(s) {sorted(unknown)}; the fields are "
                                f"{', '.join(_FIELDS)}")
    values = {name: _value(name, value, where) for name, value in row.items()}
    task = BatchTask(**{"gripper": None, **values})
    if not task.gripper:
        raise InvalidInputError(f"{where}: no gripper: give a bundled name or a URDF path")
    if (task.object is None) == (task.scene is None):
        raise InvalidInputError(f"{where}: give one of object and scene")
    if task.units not in UNITS:
        raise InvalidInputError(f"{where}: units {task.units!r} must be one of {', '.join(UNITS)}")
    if task.rank not in RANKINGS:
        raise InvalidInputError(f"{where}: rank {task.rank!r} must be one of {', '.join(RANKINGS)}")
    unknown = set(task.quality) - set(QUALITY_FIELDS)
    if unknown:
        raise InvalidInputError(f"{where}: quality takes {', '.join(QUALITY_FIELDS)}, not "
                                f"{', '.join(sorted(unknown))}")
    if task.quality and task.rank == "fit":
        raise InvalidInputError(f"{where}: quality parameters rank grasps by quality: drop them "
                                "or set rank: quality")
    try:
        task.quality_config()
    except (ConfigError, InvalidInputError) as err:
        raise InvalidInputError(f"{where}: quality: {err}") from None
    for name, low in (("samples", 1), ("seed", 0), ("top", 1)):
        if getattr(task, name) is not None and getattr(task, name) < low:
            raise InvalidInputError(f"{where}: {name} must be >= {low}, got {getattr(task, name)}")
    if not task.scale > 0:
        raise InvalidInputError(f"{where}: scale must be > 0, got {task.scale}")
    return _resolve_paths(task, folder)


def _value(name: str, value: Any, where: str) -> Any:
    """A field's value in its type: text (CSV) is converted, typed YAML values checked."""
    kind = _FIELDS[name].type
    if name in _PARAMETER_MAPS:
        if name == "repair" and (value is None or str(value).lower() in ("none", "off", "false")):
            return None
        if isinstance(value, Mapping):
            return dict(value)
        if isinstance(value, str):
            return _words(value, name, where)
    elif "int" in kind and "float" not in kind:
        if isinstance(value, int) and not isinstance(value, bool) or value is None:
            return value
        if isinstance(value, str) and value.strip().lstrip("-").isdigit():
            return int(value)
    elif "float" in kind:
        if value is None or isinstance(value, (int, float)) and not isinstance(value, bool):
            return value
        try:
            return float(value)
        except ValueError:
            if name == "table" and value == "auto":
                return value
    elif isinstance(value, (str, int, float)) and not isinstance(value, bool) or value is None:
        return None if value is None else str(value)
    raise InvalidInputError(f"{where}: {name} {value!r} is not a valid {name} (docs/batch.md)")


def _words(text: str, name: str, where: str) -> dict[str, Any]:
    """``KEY=VALUE`` words separated by spaces; values that read as numbers become numbers."""
    out: dict[str, Any] = {}
    for word in text.split():
        key, eq, value = word.partition("=")
        if not eq or not key:
            raise InvalidInputError(f"{where}: {name} word {word!r} must look like KEY=VALUE")
        out[key] = number_or_text(value)
    return out


def _resolve_paths(task: BatchTask, folder: Path) -> BatchTask:
    """The task with its relative file paths read from ``folder``; bundled gripper names and
    ``shape:``/``asset:`` specs are kept as they are."""
    from ..gripper.bundled import bundled_grippers

    def resolved(value: str | None) -> str | None:
        if value is None or value.startswith(("shape:", "asset:")) or Path(value).is_absolute():
            return value
        return str(folder / value)

    gripper = task.gripper if task.gripper in bundled_grippers() else resolved(task.gripper)
    pose = task.camera_pose
    if pose is not None and "," in pose:  # 16 numbers, not a file
        pose_resolved = pose
    else:
        pose_resolved = resolved(pose)
    return replace(task, gripper=gripper, object=resolved(task.object), scene=resolved(task.scene),
                   camera_pose=pose_resolved)
