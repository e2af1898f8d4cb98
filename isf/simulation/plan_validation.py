"""The physics test of a plan's best grasps, read from and written into its JSON form.

The gripper and the object are loaded again from the names the plan records (``gripper``:
a bundled name or URDF path; ``object``: a path or ``shape:``/``asset:`` spec), or from the
ones given. A plan on a scene, or on a point cloud, has no closed surface to give the object
a volume, a mass distribution and convex parts: it is refused (``InvalidInputError``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..exceptions import InvalidInputError
from ..gripper.loading import load_gripper
from ..gripper.model import Gripper
from ..object.specs import open_object
from .dependencies import require_simulator
from .grasp_test import GraspValidation, validate_grasp
from .object_body import ObjectBody, object_body
from .settings import SimulationSettings

__all__ = ["PlanValidation", "validate_plan"]


class PlanValidation(NamedTuple):
    """The tested grasps of a plan.

    Attributes:
        plan: the plan dict with ``validation`` added to each tested grasp and
            ``validation_settings`` at the top.
        results: one :class:`GraspValidation` per tested grasp, in rank order.
    """

    plan: dict
    results: tuple[GraspValidation, ...]


def _object(plan: dict, spec: str | None, settings: SimulationSettings) -> ObjectBody:
    if plan.get("scene") is not None:
        raise InvalidInputError("isf validate does not simulate plans on scenes: plan the object's "
                                "mesh instead (its volume and mass are unknown from camera views)")
    source = spec or plan["object"]
    try:
        obj = open_object(source)
    except (OSError, KeyError) as error:
        raise InvalidInputError(f"cannot open the plan's object {source!r}: give it with --object "
                                f"({error})") from None
    if obj.mesh_vertices is None or obj.mesh_faces is None:
        raise InvalidInputError(f"object {source!r} is a point cloud: isf validate needs a closed "
                                "mesh (give one with --object)")
    return object_body(obj.mesh_vertices, obj.mesh_faces, settings.mass, settings.part_tolerance)


def validate_plan(plan: dict, *, top: int = 5, settings: SimulationSettings | None = None,
                  gripper: Gripper | str | None = None, object_spec: str | None = None
                  ) -> PlanValidation:
    """Simulate the best ``top`` grasps of ``plan`` (the dict of a plan file).

    Args:
        plan: the plan as read from its JSON file (not modified).
        top: how many grasps to test, in the file's order (best first).
        settings: the physics test's parameters; default
            :meth:`isf.simulation.SimulationSettings.for_plan`, the friction and mass the plan
            was ranked with.
        gripper: the gripper, or its name or URDF path; default the plan's ``gripper``.
        object_spec: the object's path or spec; default the plan's ``object``.

    Raises:
        InvalidInputError: a plan on a scene or a point cloud, an object that cannot be opened,
            ``top`` < 1.
        GripperDescriptionError: the gripper cannot be loaded.
    """
    if top < 1:
        raise InvalidInputError(f"--top {top}: test at least one grasp")
    require_simulator()
    settings = settings or SimulationSettings.for_plan(plan)
    if not isinstance(gripper, Gripper):
        gripper = load_gripper(gripper or plan["gripper"])
    body = _object(plan, object_spec, settings)
    out = dict(plan)
    out["grasps"] = [dict(g) for g in plan["grasps"]]
    out["validation_settings"] = settings.to_dict()
    results = []
    for grasp in out["grasps"][:top]:
        missing = sorted(set(gripper.joint_names) - set(grasp["joints"]))
        if missing:
            raise InvalidInputError(f"grasp {grasp['rank']} has no value for joints {missing}: "
                                    f"is the plan for gripper {gripper.name!r}?")
        q = np.array([grasp["joints"][n] for n in gripper.joint_names], dtype=float)
        result = validate_grasp(gripper, body, np.asarray(grasp["T_object_gripper"], dtype=float),
                                q, settings)
        grasp["validation"] = result.to_dict()
        results.append(result)
    return PlanValidation(out, tuple(results))
