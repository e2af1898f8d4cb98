"""The quality record of one grasp (:func:`grasp_quality`) and the ranking it gives
(:func:`quality_rank_key`).

:func:`grasp_quality` builds the grasp's contacts (:func:`isf.quality.contacts.grasp_contacts`), their
edge wrenches about the object's centre of mass (:func:`object_properties`), and reports the
Ferrari-Canny epsilon, force closure and the largest gravity load per direction
(:mod:`isf.quality.wrenches`, :mod:`isf.quality.gravity`) as a :class:`GraspQuality`.

Ranking (:func:`quality_rank_key`, the planner's default ``rank="quality"``): grasps that resist
their weight in every gravity direction (smallest margin >= :data:`MARGIN_TARGET`) tie on the
first criterion; the others follow, higher smallest margin first. Then the grasp whose contacts'
centroid lies nearer the centre of mass first (:attr:`GraspQuality.com_offset`: the smaller the
gravity torques it must resist, the less its hold depends on the contact model's torsion, which
corner contacts overstate for a real pad, and on the mass distribution), then higher epsilon,
then the fitting error (mean point-to-plane distance).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from .contacts import ContactModelConfig, Contacts, grasp_contacts
from .gravity import GRAVITY, SIX_DIRECTIONS, gravity_loads
from .wrenches import CONE_EDGES, WrenchSpace, contact_wrenches

__all__ = ["GraspQuality", "MARGIN_TARGET", "ObjectProperties", "QualityConfig",
           "contacts_quality", "grasp_quality", "object_properties", "quality_rank_key"]

MARGIN_TARGET = 1.0
"""Smallest gravity margin (multiples of the object's weight) at which :func:`quality_rank_key`
counts a grasp as holding in every direction."""


@dataclass(frozen=True)
class QualityConfig:
    """Parameters of :func:`grasp_quality`.

    Attributes:
        friction: Coulomb friction coefficient between gripper and object (default 0.5, a
            rubber-like pad on plastic or cardboard; 0 gives frictionless contacts).
        cone_edges: edges of each linearised friction cone.
        grip_force: the normal forces of all contacts sum to at most this, newtons (e.g. a
            parallel gripper squeezing with 10 N per finger).
        mass: the object's mass, kilograms (gravity margins are loads over ``mass * g``).
        contact_model: how contacts are built from a grasp (its ``contact_distance`` is replaced
            by the fit's :attr:`isf.FitConfig.contact_distance` in :func:`isf.plan`).
    """

    friction: float = 0.5
    cone_edges: int = CONE_EDGES
    grip_force: float = 20.0
    mass: float = 0.3
    contact_model: ContactModelConfig = field(default_factory=ContactModelConfig)

    def __post_init__(self) -> None:
        from ..exceptions import InvalidInputError

        if not (np.isfinite(self.friction) and self.friction >= 0):
            raise InvalidInputError(f"friction must be a number >= 0, got {self.friction!r}")
        for name in ("grip_force", "mass"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InvalidInputError(f"{name} must be a number > 0, got {value!r}")
        if isinstance(self.cone_edges, bool) or int(self.cone_edges) != self.cone_edges \
                or self.cone_edges < 3:
            raise InvalidInputError(f"cone_edges must be an integer >= 3, got {self.cone_edges!r}")


@dataclass(frozen=True)
class ObjectProperties:
    """What the metrics need of the object, object frame.

    Attributes:
        center_of_mass: (3,), metres: a closed mesh's (uniform density, trimesh's mass
            properties), else the area-weighted centroid of a mesh's surface, else the mean of
            a cloud's points (a scene: what the cameras saw).
        radius: largest distance from the centre of mass to a surface point, metres (torques
            are divided by it).
    """

    center_of_mass: np.ndarray
    radius: float


def object_properties(obj: ObjectSurface) -> ObjectProperties:
    """The centre of mass and radius of ``obj`` (see :class:`ObjectProperties`)."""
    center = obj.centroid
    if obj.is_mesh:
        import trimesh

        mesh = trimesh.Trimesh(obj.mesh_vertices, obj.mesh_faces, process=False)
        center = mesh.center_mass if mesh.is_volume else mesh.triangles_center.T @ (
            mesh.area_faces / mesh.area)
    center = np.asarray(center, dtype=float)
    radius = float(np.linalg.norm(obj.points - center, axis=1).max())
    return ObjectProperties(center, max(radius, 1e-6))


@dataclass(frozen=True)
class GraspQuality:
    """How well a grasp's contacts resist loads (see :mod:`isf.quality`).

    Attributes:
        friction: the friction coefficient used.
        epsilon: Ferrari-Canny epsilon of the grasp wrench space (torques over the object
            radius), newtons per newton of total normal force; 0 without force closure.
        force_closure: the origin lies strictly inside the grasp wrench space.
        gravity_load: per gravity direction (object frame, :data:`isf.quality.gravity.SIX_DIRECTIONS`),
            the largest load resisted, newtons.
        gravity_margin: the same over the object's weight (``mass * g``).
        contacts: point contacts of the contact model.
        patches: contact patches.
        radius: the object radius torques were divided by, metres.
        com_offset: distance from the centroid of the contacts to the centre of mass, metres
            (the object radius when there are no contacts).
    """

    friction: float
    epsilon: float
    force_closure: bool
    gravity_load: dict[str, float]
    gravity_margin: dict[str, float]
    contacts: int
    patches: int
    radius: float
    com_offset: float

    @property
    def min_margin(self) -> float:
        """The smallest gravity margin over the directions (0 when there are none)."""
        return min(self.gravity_margin.values(), default=0.0)

    @property
    def holds(self) -> bool:
        """True when the grasp resists its weight in every direction (margin >= 1)."""
        return self.min_margin >= MARGIN_TARGET

    def to_dict(self) -> dict:
        """A JSON-ready record."""
        return {"friction": self.friction, "epsilon": self.epsilon,
                "force_closure": self.force_closure, "gravity_load": dict(self.gravity_load),
                "gravity_margin": dict(self.gravity_margin), "min_margin": self.min_margin,
                "contacts": self.contacts, "patches": self.patches, "radius": self.radius,
                "com_offset": self.com_offset}


def contacts_quality(contacts: Contacts, properties: ObjectProperties,
                     config: QualityConfig | None = None) -> GraspQuality:
    """The :class:`GraspQuality` of given contacts on an object with ``properties``."""
    config = QualityConfig() if config is None else config
    center, radius = properties.center_of_mass, properties.radius
    directions = np.array(list(SIX_DIRECTIONS.values()))
    space = WrenchSpace(contact_wrenches(contacts, config.friction, center, radius,
                                         config.cone_edges) if contacts.count else np.empty((0, 6)))
    if space.force_closure:  # where the ray of each load leaves the wrench space
        loads = config.grip_force * space.reach(np.hstack([-directions, np.zeros((6, 3))]))
    else:
        loads = gravity_loads(contacts, config.friction, center, directions, config.grip_force,
                              config.cone_edges)
    weight = config.mass * GRAVITY
    return GraspQuality(
        friction=float(config.friction), epsilon=space.epsilon, force_closure=space.force_closure,
        gravity_load={n: float(v) for n, v in zip(SIX_DIRECTIONS, loads)},
        gravity_margin={n: float(v / weight) for n, v in zip(SIX_DIRECTIONS, loads)},
        contacts=contacts.count, patches=contacts.patches, radius=float(radius),
        com_offset=float(np.linalg.norm(contacts.points.mean(axis=0) - center))
        if contacts.count else float(radius))


def grasp_quality(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
                  q: np.ndarray, config: QualityConfig | None = None,
                  properties: ObjectProperties | None = None) -> GraspQuality:
    """The quality of the gripper at pose ``T_object_gripper`` (4, 4, gripper frame in the
    object frame) and joints ``q`` (n_joints,) on ``obj``; ``properties`` default
    :func:`isf.quality.grasp_quality.object_properties` of ``obj`` (pass them when scoring many
    grasps of one object)."""
    config = QualityConfig() if config is None else config
    properties = object_properties(obj) if properties is None else properties
    contacts = grasp_contacts(gripper, obj, T_object_gripper, q, config.contact_model)
    return contacts_quality(contacts, properties, config)


def quality_rank_key(quality: GraspQuality | None, mean_distance: float) -> tuple:
    """Sort key (lower first) of a grasp by its quality (smallest gravity margin up to
    :data:`MARGIN_TARGET`, then :attr:`GraspQuality.com_offset`, then epsilon), then its fitting
    error ``mean_distance`` (metres); a grasp without a quality record (None) comes after every
    grasp with one."""
    if quality is None:
        return (1, 0.0, 0.0, 0.0, mean_distance)
    return (0, -min(quality.min_margin, MARGIN_TARGET), quality.com_offset, -quality.epsilon,
            mean_distance)
