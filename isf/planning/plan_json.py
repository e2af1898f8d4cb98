"""The JSON form of a :class:`~isf.planning.planner.PlanResult` (schema: ``isf/plan.schema.json``).

All lengths are metres and angles radians; ``T_object_gripper`` is the pose of
the gripper frame (the URDF root link) in the object frame, as nested row lists. For a plan on
a scene (:mod:`isf.scene`) the object frame is the scene frame, and ``scene`` records the
cameras' poses ``T_scene_camera``, the table plane (points ``x`` with ``normal . x < offset``
are below it) and the point counts.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..output_files import write_atomically
from .planner import Grasp, PlanResult

__all__ = ["PREGRASP_DISTANCE", "Provenance", "SCHEMA_PATH", "SCHEMA_VERSION", "plan_json_text",
           "plan_to_dict", "quaternion_xyzw", "write_plan_json"]

SCHEMA_PATH = Path(__file__).with_name("plan.schema.json")
"""The JSON Schema (draft 2020-12) every file written by :func:`write_plan_json` follows."""


SCHEMA_VERSION = 2
"""The version of the plan file's layout. Version 2 adds the robot-ready fields (``tcp``,
``pregrasp``, ``joint_state``, ``provenance``) and ``duplicate_of``, and keeps every field of
version 1."""

PREGRASP_DISTANCE = 0.1
"""Default distance the pre-grasp pose backs off from the grasp along the approach axis, m."""


def _number(x: float) -> float | None:
    """JSON has no inf/nan: write them as null."""
    return float(x) if math.isfinite(x) else None


def _grasp_to_dict(rank: int, grasp: Grasp) -> dict:
    fit, col = grasp.fit, grasp.collision
    return {
        "rank": rank,
        "T_object_gripper": [[float(v) for v in row] for row in grasp.T_object_gripper],
        "joints": grasp.joints,
        "error": {
            "mean_distance": _number(fit.mean_distance),
            "normal_misalignment": _number(fit.normal_misalignment),
            "total": _number(fit.error),
            "n_pairs": fit.n_pairs,
            "surface_contact": fit.surface_contact,
        },
        "status": fit.status.value,
        "iterations": fit.iterations,
        "collision_free": bool(col.collision_free),
        "clearance": _number(col.clearance),
        "penetration": _number(col.penetration),
        "colliding_links": list(col.colliding_links),
        "sampler": dict(grasp.sampler_record),
        "sample_index": grasp.sample_index,
        "valid": bool(grasp.valid),
        "pieces": grasp.pieces,
        "repaired": bool(grasp.repaired),
        "centred": bool(grasp.centred),
        "settled": grasp.settled,
        "within_bound": grasp.within_bound,
        "quality": None if grasp.quality is None else grasp.quality.to_dict(),
        "closing_obstructed_by": (None if grasp.closing_obstructed_by is None
                                  else list(grasp.closing_obstructed_by)),
        "convergence": _convergence(fit),
    }


def _short(x: float) -> float | None:
    """A finite number to 5 significant digits (enough for a plot), else null."""
    return float(f"{x:.5g}") if math.isfinite(x) else None


def _convergence(fit) -> dict:
    """The fit's history as arrays (the paper's Fig. 5): its start, then one entry per ISF
    iteration."""
    history = fit.history
    return {
        "level": [int(r.level) for r in history],
        "mean_distance": [_short(r.mean_distance) for r in history],
        "joints": {name: [_short(r.q[j]) for r in history] for j, name in enumerate(fit.joints)},
        "ipfo_iterations": [len(r.ipfo_errors) for r in history],
    }


def plan_to_dict(result: PlanResult, *, top: int | None = None,
                 pregrasp_distance: float = PREGRASP_DISTANCE,
                 provenance: Provenance | None = None) -> dict:
    """The plan as a JSON-ready dict; ``top`` keeps only the best ``top`` grasps.

    ``pregrasp_distance`` (metres, >= 0) backs each grasp's pre-grasp pose off along the
    approach axis; ``provenance`` adds what the plan's inputs were (:class:`Provenance`).
    """
    grasps = result.grasps if top is None else result.grasps[:top]
    s = result.stats
    robot = _RobotFrames.of(result, pregrasp_distance)
    return {
        "schema_version": SCHEMA_VERSION,
        "provenance": _provenance_to_dict(result, provenance or Provenance(), pregrasp_distance),
        "tcp": None if robot is None else robot.to_dict(),
        "diversity": None if result.diversity is None else asdict(result.diversity),
        "ranking": {"rank": result.rank,
                    "quality": None if result.quality is None else asdict(result.quality)},
        "gripper": result.gripper,
        "object": result.object,
        "units": "m",
        "sampler": result.sampler,
        "seed": result.seed,
        "grasps": [_grasp_to_dict(rank, g) | _robot_grasp(g, robot)
                   for rank, g in enumerate(grasps, start=1)],
        "stats": {
            "samples": s.samples,
            "collision_free": s.collision_free,
            "valid": s.valid,
            "total_time": s.total_time,
            "time_per_collision_free": _number(s.time_per_collision_free),
            "fit_time": s.fit_time,
            "collision_time": s.collision_time,
            "setup_time": s.setup_time,
            "batch_size": s.batch_size,
            "surface_points": s.surface_points,
            "workers": s.workers,
            "quality_time": s.quality_time,
            "centring_time": s.centring_time,
        },
        "config": result.config.to_dict(),
        "repair": None if result.repair is None else asdict(result.repair),
        "centring": None if result.centring is None else asdict(result.centring),
        "scene": None if result.scene is None else _scene_to_dict(result.scene),
    }


def _matrix(T: np.ndarray) -> list[list[float]]:
    return [[float(v) for v in row] for row in T]


def quaternion_xyzw(R: np.ndarray) -> list[float]:
    """The unit quaternion of rotation matrix ``R`` (3, 3), in the order x, y, z, w, with
    w >= 0 (Shepperd's method: the largest of the four squares is taken first)."""
    R = np.asarray(R, dtype=float)
    t = np.trace(R)
    squares = np.array([1 + 2 * R[0, 0] - t, 1 + 2 * R[1, 1] - t, 1 + 2 * R[2, 2] - t, 1 + t])
    k = int(np.argmax(squares))
    q = np.empty(4)
    q[k] = 0.5 * math.sqrt(squares[k])
    f = 0.25 / q[k]
    if k == 3:
        q[:3] = f * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    else:
        i, j = (k + 1) % 3, (k + 2) % 3
        q[3] = f * (R[j, i] - R[i, j])
        q[i] = f * (R[i, k] + R[k, i])
        q[j] = f * (R[j, k] + R[k, j])
    q = q / np.linalg.norm(q)
    return [float(v) for v in (q if q[3] >= 0 else -q)]


def _pose(T: np.ndarray) -> dict:
    """A pose as the 4x4 matrix and as position + quaternion (x, y, z, w)."""
    return {"matrix": _matrix(T), "position": [float(v) for v in T[:3, 3]],
            "quaternion_xyzw": quaternion_xyzw(T[:3, :3])}


@dataclass(frozen=True)
class _RobotFrames:
    """What a robot needs of the gripper: its TCP, approach axis and open joints."""

    gripper: object  # isf.Gripper
    T_gripper_tcp: np.ndarray
    approach: np.ndarray  # unit, gripper frame
    pregrasp_distance: float
    open_joints: dict

    @classmethod
    def of(cls, result: PlanResult, pregrasp_distance: float) -> _RobotFrames | None:
        from ..exceptions import InvalidInputError

        if not (isinstance(pregrasp_distance, (int, float)) and pregrasp_distance >= 0
                and math.isfinite(pregrasp_distance)):
            raise InvalidInputError(f"pregrasp_distance must be a distance >= 0 in metres, got "
                                    f"{pregrasp_distance!r}")
        g = result.gripper_model
        if g is None:
            return None
        return cls(g, g.T_root_tcp, g.approach_root, float(pregrasp_distance),
                   g.joint_state(g.q_open))

    def to_dict(self) -> dict:
        g = self.gripper
        return {"link": g.tcp_link, "declared": g.tcp_link is not None,
                "T_gripper_tcp": _matrix(self.T_gripper_tcp),
                "approach": [float(v) for v in self.approach],
                "pregrasp_distance": self.pregrasp_distance, "quaternion_order": "xyzw",
                "open_joints": self.open_joints}


def _robot_grasp(grasp: Grasp, robot: _RobotFrames | None) -> dict:
    """A grasp's robot-ready fields: the TCP pose, the pre-grasp, every joint by URDF name."""
    out = {"duplicate_of": grasp.duplicate_of}
    if robot is None:
        return out
    T_object_tcp = grasp.T_object_gripper @ robot.T_gripper_tcp
    back = np.eye(4)  # the gripper moved back against its approach, in its own frame
    back[:3, 3] = -robot.pregrasp_distance * robot.approach
    T_pre = grasp.T_object_gripper @ back
    out.update({
        "tcp": _pose(T_object_tcp),
        "joint_state": robot.gripper.joint_state(grasp.q),
        "pregrasp": {"tcp": _pose(T_pre @ robot.T_gripper_tcp),
                     "T_object_gripper": _matrix(T_pre), "joint_state": robot.open_joints},
    })
    return out


@dataclass(frozen=True)
class Provenance:
    """Where a plan came from, beyond what :class:`PlanResult` records.

    Attributes:
        object_file: the object's file, hashed into the provenance (None: a built-in shape or
            an array).
        units: the object file's units as read (``m``, ``cm``, ``mm``).
        scale: the extra scale factor applied to the object.
        parameters: every other parameter of the run (the command line's options), JSON-ready.
    """

    object_file: str | Path | None = None
    units: str = "m"
    scale: float = 1.0
    parameters: Mapping = field(default_factory=dict)


def _sha256(path: Path | None) -> str | None:
    if path is None or not Path(path).is_file():
        return None
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _provenance_to_dict(result: PlanResult, p: Provenance, pregrasp_distance: float) -> dict:
    from .. import __version__

    g = result.gripper_model
    gripper_file = None if g is None or g.urdf_path is None else Path(g.urdf_path).resolve()
    object_file = None if p.object_file is None else Path(p.object_file).resolve()
    s = result.stats
    return {
        "isf_version": __version__,
        "gripper_file": None if gripper_file is None else str(gripper_file),
        "gripper_sha256": _sha256(gripper_file),
        "object_file": None if object_file is None else str(object_file),
        "object_sha256": _sha256(object_file),
        "units": p.units, "scale": float(p.scale),
        "sampler": result.sampler, "seed": result.seed,
        "parameters": {**dict(p.parameters), "samples": s.samples, "batch_size": s.batch_size,
                       "workers": s.workers, "pregrasp_distance": pregrasp_distance},
    }


def _scene_to_dict(scene) -> dict:
    """What a plan on a scene was planned in: the cameras, the table, the points seen."""
    table = scene.table
    return {
        "T_scene_camera": [[[float(v) for v in row] for row in T] for T in scene.T_scene_camera],
        "table": None if table is None else {"normal": [float(v) for v in table.normal],
                                             "offset": float(table.offset)},
        "observed_points": int(scene.observed),
        "surface_points": int(scene.surface.n_points),
        "pieces": int(scene.segments.count),
    }


def _dumps(value, indent: str = "") -> str:
    """JSON indented by two spaces per level, with every list of numbers, strings or nulls on
    one line (the per-iteration arrays of ``convergence`` stay short)."""
    inner = indent + "  "
    if isinstance(value, dict) and value:
        items = (f"{inner}{json.dumps(k)}: {_dumps(v, inner)}" for k, v in value.items())
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    if isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        return "[\n" + ",\n".join(inner + _dumps(v, inner) for v in value) + "\n" + indent + "]"
    return json.dumps(value)


def plan_json_text(result: PlanResult, **options) -> str:
    """The plan file's text (ending in a newline); ``options`` as for :func:`plan_to_dict`."""
    return _dumps(plan_to_dict(result, **options)) + "\n"


def write_plan_json(result: PlanResult, path: str | Path, *, top: int | None = None,
                    **options) -> Path:
    """Write the plan to ``path`` atomically (a complete file or none at all), with the
    permissions of a plain new file (``0o666`` less the umask).

    Returns:
        the path written.

    Raises:
        OutputFileError: ``path`` is a folder, a symbolic link or a FIFO, or cannot be written
            (:func:`isf.output_files.write_atomically`).
    """
    text = plan_json_text(result, top=top, **options)
    return write_atomically(path, text.encode("utf-8"), "plan file")
