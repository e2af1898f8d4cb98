"""Collision repair of a fitted grasp: push penetrating links out, keep the contacts.

:func:`repair_penetration` and :class:`ClearanceRepair` (module :mod:`isf.repair.clearance`)
solve a small dense QP per step (daqp, a maintained dual active-set solver) on clearance rows
(:mod:`isf.repair.rows`) built from geometry prepared once (``_geometry``), with contact pairs
(``_contacts``) and the step's arithmetic (``_step``) compiled.
"""

from .clearance import ClearanceRepair, RepairConfig, RepairResult, repair_penetration

__all__ = ["ClearanceRepair", "RepairConfig", "RepairResult", "repair_penetration"]
