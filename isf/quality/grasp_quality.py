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
from functools import cached_property, total_ordering

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from .contacts import ContactModelConfig, Contacts, grasp_contacts
from .gravity import GRAVITY, SIX_DIRECTIONS, gravity_loads, resists_loads
from .wrenches import CONE_EDGES, WrenchSpace, contact_wrenches, positively_spans

__all__ = ["GraspQuality", "MARGIN_TARGET", "ObjectProperties", "QualityConfig",
           "contacts_quality", "grasp_quality", "object_properties", "quality_rank_key"]

MARGIN_TARGET = 1.0
"""Smallest gravity margin (multiples of the object's weight) at which :func:`quality_rank_key`
counts a grasp as holding in every direction."""

_DIRECTIONS = np.array(list(SIX_DIRECTIONS.values()))


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


class GraspQuality:
    """How well a grasp's contacts resist loads (see :mod:`isf.quality`), from its contacts on an
    object with given :class:`ObjectProperties` under a :class:`QualityConfig`.

    What the ranking needs is computed at once: :attr:`com_offset` and :attr:`held_margin`,
    which for a grasp that holds its weight in every direction is a feasibility test per
    direction (:func:`isf.quality.gravity.resists_loads`), no wrench space. The grasp wrench
    space (:class:`isf.quality.wrenches.WrenchSpace`) and the largest loads are built when one
    of :attr:`epsilon`, :attr:`force_closure`, :attr:`gravity_load`, :attr:`gravity_margin` or
    :attr:`min_margin` is first read (a plan file writes them for the grasps it keeps), then kept.

    Attributes:
        friction: the friction coefficient used.
        contacts: number of point contacts of the contact model.
        patches: number of contact patches.
        radius: the object radius torques were divided by, metres.
        com_offset: distance from the centroid of the contacts to the centre of mass, metres
            (the object radius when there are no contacts).
        held_margin: the smallest gravity margin capped at :data:`MARGIN_TARGET`:
            ``min(min_margin, MARGIN_TARGET)``.
    """

    def __init__(self, contacts: Contacts, properties: ObjectProperties,
                 config: QualityConfig | None = None):
        config = QualityConfig() if config is None else config
        self._contacts, self._properties, self._config = contacts, properties, config
        self.friction = float(config.friction)
        self.contacts = contacts.count
        self.patches = contacts.patches
        self.radius = float(properties.radius)
        self.com_offset = (float(np.linalg.norm(contacts.points.mean(axis=0)
                                                - properties.center_of_mass))
                           if contacts.count else self.radius)
        weight = config.mass * GRAVITY
        resisted = resists_loads(contacts, config.friction, properties.center_of_mass,
                                 _DIRECTIONS, MARGIN_TARGET * weight, config.grip_force,
                                 config.cone_edges, properties.radius, until_failure=True)
        if resisted.all():
            self.held_margin = MARGIN_TARGET
        elif not self._origin_may_be_inside and not resists_loads(
                contacts, config.friction, properties.center_of_mass, _DIRECTIONS, 1.0, None,
                config.cone_edges, properties.radius, until_failure=True).all():
            self.held_margin = 0.0  # a direction in which no grip resists any load
        else:
            self.held_margin = min(self.min_margin, MARGIN_TARGET)

    def __repr__(self) -> str:
        return (f"GraspQuality(friction={self.friction}, contacts={self.contacts}, "
                f"patches={self.patches}, com_offset={self.com_offset:.4g}, "
                f"held_margin={self.held_margin:.4g})")

    @cached_property
    def _wrenches(self) -> np.ndarray:
        contacts, properties, config = self._contacts, self._properties, self._config
        return (contact_wrenches(contacts, config.friction, properties.center_of_mass,
                                 properties.radius, config.cone_edges)
                if contacts.count else np.empty((0, 6)))

    @cached_property
    def _space(self) -> WrenchSpace:
        return WrenchSpace(self._wrenches)

    @cached_property
    def _origin_may_be_inside(self) -> bool:
        """False when the origin is outside the wrench space, shown without its hull
        (:func:`isf.quality.wrenches.positively_spans`): the wrench space is then not built."""
        return "_space" in self.__dict__ or positively_spans(self._wrenches)

    @property
    def epsilon(self) -> float:
        """Ferrari-Canny epsilon of the grasp wrench space (torques over the object radius),
        newtons per newton of total normal force; 0 without force closure."""
        return self._space.epsilon if self._origin_may_be_inside else 0.0

    @property
    def force_closure(self) -> bool:
        """The origin lies strictly inside the grasp wrench space."""
        return bool(self._origin_may_be_inside and self._space.force_closure)

    @cached_property
    def gravity_load(self) -> dict[str, float]:
        """Per gravity direction (object frame, :data:`isf.quality.gravity.SIX_DIRECTIONS`), the
        largest load resisted, newtons."""
        config, properties = self._config, self._properties
        if self.force_closure:  # where the ray of each load leaves the wrench space
            loads = config.grip_force * self._space.reach(
                np.hstack([-_DIRECTIONS, np.zeros((len(_DIRECTIONS), 3))]))
        else:
            loads = gravity_loads(self._contacts, config.friction, properties.center_of_mass,
                                  _DIRECTIONS, config.grip_force, config.cone_edges)
        return {n: float(v) for n, v in zip(SIX_DIRECTIONS, loads)}

    @property
    def gravity_margin(self) -> dict[str, float]:
        """:attr:`gravity_load` over the object's weight (``mass * g``)."""
        weight = self._config.mass * GRAVITY
        return {n: v / weight for n, v in self.gravity_load.items()}

    @property
    def min_margin(self) -> float:
        """The smallest gravity margin over the directions (0 when there are none)."""
        return min(self.gravity_margin.values(), default=0.0)

    @property
    def holds(self) -> bool:
        """True when the grasp resists its weight in every direction (margin >= 1)."""
        return self.held_margin >= MARGIN_TARGET

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
    return GraspQuality(contacts, properties, config)


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


@total_ordering
class _HigherEpsilonFirst:
    """A sort-key element that orders grasps by higher epsilon first and reads the epsilon
    (building the wrench space) only when the elements before it in the key tie."""

    __slots__ = ("quality",)
    __hash__ = None

    def __init__(self, quality: GraspQuality | None):
        self.quality = quality

    def _epsilon(self) -> float:
        return 0.0 if self.quality is None else self.quality.epsilon

    def __eq__(self, other) -> bool:
        return self._epsilon() == other._epsilon()

    def __lt__(self, other) -> bool:
        return self._epsilon() > other._epsilon()


def quality_rank_key(quality: GraspQuality | None, mean_distance: float) -> tuple:
    """Sort key (lower first) of a grasp by its quality (smallest gravity margin up to
    :data:`MARGIN_TARGET`, :attr:`GraspQuality.held_margin`, then
    :attr:`GraspQuality.com_offset`, then higher epsilon, read only to break a tie of the two
    before it), then its fitting error ``mean_distance`` (metres); a grasp without a quality
    record (None) comes after every grasp with one."""
    if quality is None:
        return (1, 0.0, 0.0, _HigherEpsilonFirst(None), mean_distance)
    return (0, -quality.held_margin, quality.com_offset, _HigherEpsilonFirst(quality),
            mean_distance)
