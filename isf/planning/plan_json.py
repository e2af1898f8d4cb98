"""The JSON form of a :class:`~isf.planning.planner.PlanResult` (schema: ``isf/plan.schema.json``).

All lengths are metres and angles radians; ``T_object_gripper`` is the pose of
the gripper frame (the URDF root link) in the object frame, as nested row lists. For a plan on
a scene (:mod:`isf.scene`) the object frame is the scene frame, and ``scene`` records the
cameras' poses ``T_scene_camera``, the table plane (points ``x`` with ``normal . x < offset``
are below it) and the point counts.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

from ..output_files import write_atomically
from .planner import Grasp, PlanResult

__all__ = ["SCHEMA_PATH", "plan_to_dict", "write_plan_json"]

SCHEMA_PATH = Path(__file__).with_name("plan.schema.json")
"""The JSON Schema (draft 2020-12) every file written by :func:`write_plan_json` follows."""


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
    }


def plan_to_dict(result: PlanResult, *, top: int | None = None) -> dict:
    """The plan as a JSON-ready dict; ``top`` keeps only the best ``top`` grasps."""
    grasps = result.grasps if top is None else result.grasps[:top]
    s = result.stats
    return {
        "gripper": result.gripper,
        "object": result.object,
        "units": "m",
        "sampler": result.sampler,
        "seed": result.seed,
        "grasps": [_grasp_to_dict(rank, g) for rank, g in enumerate(grasps, start=1)],
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
        },
        "config": result.config.to_dict(),
        "repair": None if result.repair is None else asdict(result.repair),
        "scene": None if result.scene is None else _scene_to_dict(result.scene),
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


def write_plan_json(result: PlanResult, path: str | Path, *, top: int | None = None) -> Path:
    """Write the plan to ``path`` atomically (a complete file or none at all), with the
    permissions of a plain new file (``0o666`` less the umask).

    Returns:
        the path written.

    Raises:
        OutputFileError: ``path`` is a folder, a symbolic link or a FIFO, or cannot be written
            (:func:`isf.output_files.write_atomically`).
    """
    text = json.dumps(plan_to_dict(result, top=top), indent=2)
    return write_atomically(path, (text + "\n").encode("utf-8"), "plan file")
