"""A grasp file written by ``isf plan`` (docs/json-schema.md), read back with the gripper and the
object (or scene) it names, for ``isf show`` and ``isf export``.

The plan file names its gripper (``gripper``: a bundled name) and object (``object``: a file
name, ``shape:NAME`` or ``asset:NAME``). Where the file also records where they came from
(``provenance``: ``gripper_file``, ``object_file``, ``units``, ``scale`` and the run's
``parameters``: the object spec, a scene's ``intrinsics``, ``depth_scale``, ``cloud_frame``),
those are used first; options given by the caller override both.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import InvalidInputError, ISFError, ObjectLoadError

if TYPE_CHECKING:
    from ..gripper.model import Gripper
    from ..object.surface import ObjectSurface
    from ..scene.loading import Scene

__all__ = ["PlanFile", "PlanSources", "SourceOptions", "load_sources", "open_plan"]


@dataclass(frozen=True, eq=False)
class PlanFile:
    """A plan file as read.

    Attributes:
        path: the file.
        data: its JSON document.
    """

    path: Path
    data: dict

    @property
    def grasps(self) -> list[dict]:
        """The grasps, best first, as written (``rank`` from 1)."""
        return self.data["grasps"]

    @property
    def is_scene(self) -> bool:
        """True for a plan on what cameras saw (its object frame is the scene frame)."""
        return self.data.get("scene") is not None

    @property
    def provenance(self) -> Mapping:
        """The file's ``provenance`` record, or an empty mapping for a file without one."""
        value = self.data.get("provenance")
        return value if isinstance(value, Mapping) else {}

    def grasp(self, rank: int) -> dict:
        """The grasp of rank ``rank`` (from 1).

        Raises:
            InvalidInputError: no grasp has that rank.
        """
        for g in self.grasps:
            if g.get("rank") == rank:
                return g
        raise InvalidInputError(f"{self.path} has no grasp of rank {rank}: choose one of 1 to "
                                f"{len(self.grasps)}")


def open_plan(path: str | Path) -> PlanFile:
    """Read a plan file.

    Raises:
        InvalidInputError: the file is missing, not JSON, or not a plan (no ``grasps``, ``gripper``
            and ``object``).
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise InvalidInputError(f"{path} is not a file: give a grasp file written by 'isf plan --out'")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidInputError(f"{path} is not JSON ({exc}): give a grasp file written by "
                                "'isf plan --out'") from exc
    if not (isinstance(data, dict) and isinstance(data.get("grasps"), list)
            and isinstance(data.get("gripper"), str) and isinstance(data.get("object"), str)):
        raise InvalidInputError(f"{path} is not an isf grasp file (it lacks grasps, gripper or "
                                "object): give a file written by 'isf plan --out'")
    return PlanFile(path, data)


@dataclass(frozen=True)
class SourceOptions:
    """What the caller says about the plan's gripper and object; None: take it from the file.

    Attributes:
        gripper: a bundled name or a tagged URDF path.
        object_spec: an object spec (file, ``shape:NAME``, ``asset:NAME``) or, for a scene plan,
            the scene's depth image or cloud.
        units, scale: of the object file (``isf plan --units``, ``--scale``).
        intrinsics, depth_scale, cloud_frame: of a scene (``isf plan --intrinsics`` ...).
    """

    gripper: str | None = None
    object_spec: str | None = None
    units: str | None = None
    scale: float | None = None
    intrinsics: str | None = None
    depth_scale: float | None = None
    cloud_frame: str | None = None


@dataclass(frozen=True, eq=False)
class PlanSources:
    """The gripper and the object (or scene) a plan file was planned with.

    Attributes:
        gripper: the gripper.
        surface: the object's surface (a scene's observed surface), object frame.
        scene: the scene, or None for an object.
    """

    gripper: Gripper
    surface: ObjectSurface
    scene: Scene | None = None


def _parameters(provenance: Mapping) -> Mapping:
    """The run's options as the provenance records them (``isf plan``'s), or an empty mapping."""
    value = provenance.get("parameters")
    return value if isinstance(value, Mapping) else {}


def _first(*values):
    return next((v for v in values if v is not None), None)


def load_sources(plan: PlanFile, options: SourceOptions = SourceOptions()) -> PlanSources:
    """Load the gripper and the object (or scene) of ``plan``.

    Raises:
        InvalidInputError: the gripper or the object cannot be found from the file: the message
            names the option that gives it (``--gripper``, ``--object``, ``--intrinsics``).
    """
    from ..gripper.loading import load_gripper

    prov = plan.provenance
    gripper_spec = _first(options.gripper, prov.get("gripper_file"), plan.data["gripper"])
    try:
        gripper = load_gripper(gripper_spec)
    except ISFError as exc:
        raise InvalidInputError(f"the plan's gripper {gripper_spec!r} does not load ({exc}): pass "
                                "--gripper NAME|URDF") from exc
    spec = _parameters(prov).get("object")
    built_in = spec if isinstance(spec, str) and spec.startswith(("shape:", "asset:")) else None
    object_spec = _first(options.object_spec, built_in, prov.get("object_file"),
                         plan.data["object"])
    try:
        if plan.is_scene:
            scene = _load_scene(plan, object_spec, options)
            return PlanSources(gripper, scene.surface, scene)
        from ..object.specs import open_object

        units = _first(options.units, prov.get("units"), "m")
        scale = _first(options.scale, prov.get("scale"), 1.0)
        return PlanSources(gripper, open_object(object_spec, units=units, scale=float(scale)))
    except (ObjectLoadError, InvalidInputError) as exc:
        what = "scene" if plan.is_scene else "object"
        raise InvalidInputError(f"the plan's {what} {object_spec!r} does not load ({exc}): pass "
                                "--object FILE (and its --units/--scale, or for a scene "
                                "--intrinsics/--depth-scale/--cloud-frame)") from exc


def _load_scene(plan: PlanFile, source: str, options: SourceOptions):
    """The scene of a scene plan: its cameras' poses and table from the file."""
    from ..collision.checker import Plane
    from ..scene import load_scene

    params, recorded = _parameters(plan.provenance), plan.data["scene"]
    poses = np.asarray(recorded["T_scene_camera"], dtype=float)
    table = recorded.get("table")
    return load_scene(
        source,
        intrinsics=_first(options.intrinsics, params.get("intrinsics")),
        T_scene_camera=poses[0],
        depth_scale=_first(options.depth_scale, params.get("depth_scale")),
        cloud_frame=_first(options.cloud_frame, params.get("cloud_frame"), "camera"),
        table=None if table is None else Plane(table["normal"], table["offset"], "table"),
    )
