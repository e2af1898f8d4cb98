"""Grasp quality: what a grasp's contacts can resist, and the ranking it gives.

:mod:`isf.quality.contacts` builds the contact model of a grasp (point and patch contacts with
friction), :mod:`isf.quality.wrenches` the friction cones, force closure and the Ferrari-Canny
epsilon, :mod:`isf.quality.gravity` the largest gravity load per direction, and
:mod:`isf.quality.grasp_quality` the per-grasp record and the planner's ranking key, and
:mod:`isf.quality.closing` the links that would take the grip from the contact surfaces as the
fingers close. Pure functions on numpy arrays (scipy's qhull and HiGHS); see docs/quality.md.
"""

from .closing import OBSTRUCTION_MARGIN, closing_obstructions
from .contacts import ContactModelConfig, Contacts, grasp_contacts, grasps_contacts
from .grasp_quality import (
    MARGIN_TARGET,
    GraspQuality,
    ObjectProperties,
    QualityConfig,
    contacts_quality,
    expected_to_hold,
    grasp_quality,
    grasps_quality,
    object_properties,
    quality_rank_key,
)
from .gravity import GRAVITY, SIX_DIRECTIONS, gravity_loads, resists_loads
from .wrenches import (
    CONE_EDGES,
    WrenchSpace,
    cone_edges,
    contact_wrenches,
    epsilon_quality,
    force_closure,
    positively_spans,
)

__all__ = ["CONE_EDGES", "ContactModelConfig", "Contacts", "GRAVITY", "GraspQuality",
           "MARGIN_TARGET", "OBSTRUCTION_MARGIN", "ObjectProperties", "QualityConfig",
           "SIX_DIRECTIONS", "WrenchSpace", "closing_obstructions", "cone_edges",
           "contact_wrenches", "contacts_quality", "epsilon_quality", "expected_to_hold",
           "force_closure", "grasp_contacts", "grasp_quality", "grasps_contacts", "grasps_quality",
           "gravity_loads", "object_properties", "positively_spans", "quality_rank_key",
           "resists_loads"]
