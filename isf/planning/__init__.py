"""Grasp planning by guided sampling (paper Algorithm 3): :func:`plan` and its results.

:func:`plan` (module :mod:`isf.planning.planner`) proposes starts with a sampler, fits them,
checks and repairs each fit (``_evaluation``) on the object thinned to the gripper's resolution
(``_working_surface``), and ranks the grasps; :mod:`isf.planning.plan_json` writes a plan as
JSON.
"""

from .planner import Grasp, PlanResult, PlanStats, plan

__all__ = ["Grasp", "PlanResult", "PlanStats", "plan"]
