"""Physics validation of grasps in MuJoCo (``isf validate``; the optional extra ``isf[sim]``).

Modules: ``settings`` (the test's parameters), ``object_body`` (the object's convex
parts and mass properties), ``world`` (the MuJoCo model of a grasp), ``grasp_test``
(close, then hold against gravity in six directions), ``plan_validation`` (a plan file's
best grasps). See docs/validate.md.
"""

from .grasp_test import DIRECTIONS, DirectionResult, GraspValidation, Outcome, validate_grasp
from .object_body import ObjectBody, object_body
from .plan_validation import PlanValidation, validate_plan
from .settings import SimulationSettings

__all__ = ["DIRECTIONS", "DirectionResult", "GraspValidation", "ObjectBody", "Outcome",
           "PlanValidation", "SimulationSettings", "object_body", "validate_grasp", "validate_plan"]
