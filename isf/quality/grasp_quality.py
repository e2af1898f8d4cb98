"""The quality record of one grasp (:func:`grasp_quality`) and the ranking it gives
(:func:`quality_rank_key`).

:func:`grasp_quality` builds the grasp's contacts (:func:`isf.quality.contacts.grasp_contacts`), their
edge wrenches about the object's centre of mass (:func:`object_properties`), and reports the
Ferrari-Canny epsilon, force closure and the largest gravity load per direction
(:mod:`isf.quality.wrenches`, :mod:`isf.quality.gravity`) as a :class:`GraspQuality`.

Ranking (:func:`quality_rank_key`, the planner's default ``rank="quality"``): grasps whose
closing fingers reach the object with their contact surfaces first
(:func:`isf.quality.closing.closing_obstructions` finds no link that could stop a contact
surface deeper in the object) first; then grasps whose squeeze is balanced
(:attr:`GraspQuality.squeeze_balanced`: with every contact surface pressing equally hard,
friction can absorb the net push); then
grasps that resist their weight in every gravity direction (smallest margin >=
:data:`MARGIN_TARGET`) tie; the others follow, higher smallest margin first. Then the grasp
whose contacts' centroid lies nearer the centre of mass first (:attr:`GraspQuality.com_offset`:
the smaller the gravity torques it must resist, the less its hold depends on the contact
model's torsion, which corner contacts overstate for a real pad, and on the mass
distribution), then higher epsilon, then the fitting error (mean point-to-plane distance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, total_ordering

import numpy as np

from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from .contacts import ContactModelConfig, Contacts, grasps_contacts
from .gravity import GRAVITY, SIX_DIRECTIONS, _LoadBalance, gravity_loads, resists_loads
from .wrenches import CONE_EDGES, WrenchSpace, _cross, contact_wrenches, positively_spans

__all__ = ["GraspQuality", "MARGIN_TARGET", "ObjectProperties", "QualityConfig",
           "contacts_quality", "expected_to_hold", "grasp_quality", "grasps_quality",
           "object_properties", "quality_rank_key"]

MARGIN_TARGET = 1.0
"""Smallest gravity margin (multiples of the object's weight) at which :func:`quality_rank_key`
counts a grasp as holding in every direction."""

_DIRECTIONS = np.array(list(SIX_DIRECTIONS.values()))

_MARGIN_RESOLUTION = 1e-7
"""The ranking narrows the bounds of a held margin below :data:`MARGIN_TARGET` by feasibility
tests down to this width (the tests' tolerance resolves margins to about 1e-8); then it computes
the margin (see :class:`_HigherMarginFirst`): only grasps whose margins lie within about
:data:`_MARGIN_SEPARATION` of each other cost their margins."""

_SAME_CONTACTS = 1e-12
""":func:`grasps_quality` gives grasps whose contact positions (metres) and normals agree to
this one record: the rounding of one fit reached twice (a few 1e-15), far below what any
metric resolves (the feasibility tests' tolerance is 1e-9 of the load)."""

_SQUEEZE_TOLERANCE = 1e-9
""":attr:`GraspQuality.squeeze_balanced` allows the imbalance this far above the friction
coefficient: the rounding of unit normals that cancel (a few 1e-16), so that opposing pads
are balanced also without friction."""

_MARGIN_SEPARATION = 1e-6
"""Bounds settle the order of two held margins only when they are this far apart (the
feasibility tests' tolerance and the wrench space's joggle are far smaller); closer, the
values (computed) decide."""


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
    """The centre of mass and radius of ``obj`` (see :class:`ObjectProperties`). A mesh's centre
    of mass is computed once and kept in its memo
    (:func:`isf.collision.surface_distance.mesh_memo`), which the sampler, the centring and the
    ranking of a plan share."""
    center = obj.centroid
    if obj.is_mesh:
        from ..collision.surface_distance import mesh_memo  # loaded by every plan already

        memo = mesh_memo(obj)
        if "center_of_mass" not in memo:
            memo["center_of_mass"] = _mesh_center_of_mass(obj.mesh_vertices, obj.mesh_faces)
        center = memo["center_of_mass"].copy()
    center = np.asarray(center, dtype=float)
    radius = float(np.linalg.norm(obj.points - center, axis=1).max())
    return ObjectProperties(center, max(radius, 1e-6))


def _mesh_center_of_mass(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The solid's centre of mass (3,) of a closed mesh (:func:`_solid_center_of_mass`), else
    the area-weighted centroid of its surface."""
    center = _solid_center_of_mass(vertices, faces)
    if center is None:  # not closed: the centroid of the surface
        import trimesh

        mesh = trimesh.Trimesh(vertices, faces, process=False)
        center = mesh.triangles_center.T @ (mesh.area_faces / mesh.area)
    return np.asarray(center, dtype=float)


def _solid_center_of_mass(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """The centre of mass (3,) of the solid of uniform density a triangle mesh (vertices (V, 3),
    faces (F, 3)) bounds, or None when it bounds none: trimesh's ``is_volume`` and
    ``center_mass`` (the same tests, the same arithmetic, the same bits) without building a
    ``trimesh.Trimesh``, whose caches cost ten times more. A mesh bounds a solid when every
    edge is shared by exactly two faces that run along it in opposite directions (closed and
    consistently wound) and its signed volume is positive (outward normals). The centre is
    the first moment of the signed tetrahedra (origin, triangle) over their volume (Eberly,
    "Polyhedral mass properties", Geometric Tools 2002, as trimesh integrates it)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if not len(faces):
        return None
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = edges.min(axis=1) * len(vertices) + edges.max(axis=1)  # the undirected edge
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    if not (np.array_equal(keys[0::2], keys[1::2]) and np.all(keys[1:-1:2] != keys[2::2])):
        return None  # an edge not shared by exactly two faces
    pairs = edges[order].reshape(-1, 4)
    if not np.array_equal(pairs[:, 1], pairs[:, 2]):
        return None  # two faces running along an edge the same way: inconsistent winding
    triangles = vertices[faces]
    sides = triangles[:, 1:, :] - triangles[:, :2, :]
    crosses = _cross(sides[:, 0], sides[:, 1])  # twice the area times the normal
    a, b, c = triangles[:, 0, :], triangles[:, 1, :], triangles[:, 2, :]
    f1 = a + b + c
    f2 = a ** 2 + b ** 2 + a * b + c * f1
    volume = (crosses[:, 0] * f1[:, 0]).sum() / 6.0
    center = np.ascontiguousarray((crosses * f2).T).sum(axis=1) / 24.0 / volume
    if not (np.isfinite(center).all() and volume > 0.0):
        return None
    return center


class GraspQuality:
    """How well a grasp's contacts resist loads (see :mod:`isf.quality`), from its contacts on an
    object with given :class:`ObjectProperties` under a :class:`QualityConfig`.

    What the ranking needs is computed at once: :attr:`com_offset`, and whether the grasp holds
    its weight in every direction, a feasibility test per direction
    (:func:`isf.quality.gravity.resists_loads`), no wrench space; then :attr:`held_margin` is
    1 (or 0 when some direction resists no load at any grip). Otherwise the ranking compares
    held margins by bounds that further feasibility tests narrow, only as far as the order
    needs (:func:`quality_rank_key`). The grasp wrench space
    (:class:`isf.quality.wrenches.WrenchSpace`) and the largest loads are built when one of
    :attr:`held_margin`, :attr:`epsilon`, :attr:`force_closure`, :attr:`gravity_load`,
    :attr:`gravity_margin` or :attr:`min_margin` is first read (a plan file writes them for the
    grasps it keeps), then kept.

    Attributes:
        friction: the friction coefficient used.
        contacts: number of point contacts of the contact model.
        patches: number of contact patches.
        radius: the object radius torques were divided by, metres.
        com_offset: distance from the centroid of the contacts to the centre of mass, metres
            (the object radius when there are no contacts).
        squeeze_imbalance: the net push on the object when every touching contact surface
            presses with the same normal force along its mean inward normal ``n_s``, per unit
            of that force and per surface: ``|sum_s n_s| / S`` over the ``S`` touching
            surfaces, in [0, 1] (0: the pushes cancel; 1: they all push one way, or there are
            no contacts). See :attr:`squeeze_balanced`.
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
        self.squeeze_imbalance = _squeeze_imbalance(contacts)
        self._weight = config.mass * GRAVITY
        self._balance = (_LoadBalance(contacts, config.friction, properties.center_of_mass,
                                      config.grip_force, config.cone_edges, properties.radius)
                         if contacts.count else None)
        # what is known of each direction's margin (capped at the target): in [low, high)
        self._direction_low = np.zeros(len(_DIRECTIONS))
        self._direction_high = np.full(len(_DIRECTIONS), np.inf)
        self._direction_step = np.full(len(_DIRECTIONS), 0.5 * _MARGIN_RESOLUTION)
        self._holds = False
        for k, d in enumerate(_DIRECTIONS):
            if self._balance is None:
                self._direction_high[k] = MARGIN_TARGET
                break
            test = self._balance.test(d, MARGIN_TARGET * self._weight)
            if not test.resisted:
                self._direction_high[k] = test.bound / self._weight
                break
            self._direction_low[k] = MARGIN_TARGET
        else:
            self.held_margin = MARGIN_TARGET
            self._holds = True
            return
        self._low, self._high = 0.0, float(self._direction_high.min())  # the smallest's bounds
        if not self._origin_may_be_inside and not resists_loads(
                contacts, config.friction, properties.center_of_mass, _DIRECTIONS, 1.0, None,
                config.cone_edges, properties.radius, until_failure=True).all():
            self.held_margin = 0.0  # a direction in which no grip resists any load

    @cached_property
    def held_margin(self) -> float:
        """The smallest gravity margin capped at :data:`MARGIN_TARGET`:
        ``min(min_margin, MARGIN_TARGET)``."""
        return min(self.min_margin, MARGIN_TARGET)

    def _margin_bounds(self) -> tuple[float, float, bool]:
        """What is known of :attr:`held_margin`: ``(value, value, True)`` once computed, else
        ``(low, high, False)`` with the margin in ``[low, high)``."""
        if "held_margin" in self.__dict__:
            return self.held_margin, self.held_margin, True
        return self._low, self._high, False

    def _refine_margin(self) -> None:
        """Narrow the bounds of :attr:`held_margin` by one feasibility test
        (:meth:`isf.quality.gravity._LoadBalance.test`), keeping each direction's bounds. The
        smallest upper bound ``u`` of a direction bounds the margin from above; a direction
        whose lower bound is below ``u`` is tested at ``u`` (likeliest to fail first); when
        only the direction of ``u`` is left, it is tested a step below ``u`` (half
        :data:`_MARGIN_RESOLUTION`, doubled after each failure, at most halfway to its lower
        bound). A failed test lowers the direction's upper bound to the Farkas bound of the
        test, which is the direction's margin (to about 1e-10) once the test lies on the
        face its load leaves the feasible loads by: the bounds close in a few tests. Bounds
        no wider than :data:`_MARGIN_RESOLUTION` are replaced by the value, computed (wrench
        space or linear programme)."""
        if "held_margin" in self.__dict__:
            return
        low, high, upper = self._direction_low, self._direction_high, self._high
        if upper - self._low <= _MARGIN_RESOLUTION:
            self.held_margin  # noqa: B018 - computes and keeps it
            return
        smallest = int(np.argmin(high))
        others = [k for k in np.argsort(high, kind="stable")  # likeliest to fail first
                  if k != smallest and low[k] < upper]
        if others:
            k, load = others[0], upper
        else:
            k = smallest
            load = max(upper - self._direction_step[k], 0.5 * (low[k] + upper))
        test = self._balance.test(_DIRECTIONS[k], load * self._weight)
        if test.resisted:
            low[k] = load
            self._direction_step[k] = 0.5 * _MARGIN_RESOLUTION
        else:
            high[k] = max(min(test.bound / self._weight, load), low[k])
            if not others:
                self._direction_step[k] *= 2.0
        self._low, self._high = float(low.min()), float(high.min())

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
        return {n: v / self._weight for n, v in self.gravity_load.items()}

    @property
    def min_margin(self) -> float:
        """The smallest gravity margin over the directions (0 when there are none)."""
        return min(self.gravity_margin.values(), default=0.0)

    @property
    def squeeze_balanced(self) -> bool:
        """True when friction can absorb the net push of an equal squeeze:
        :attr:`squeeze_imbalance` <= :attr:`friction`. With each of ``S`` surfaces pressing with
        normal force ``F``, the pushes sum to ``F |sum_s n_s|`` and the friction forces to at
        most ``mu F S``: the object can stay put while a gripper closes with force-bounded
        fingers (as ``isf validate``'s do) only if this holds. For two pads it says their
        normals are within ``2 asin(mu)`` of opposite (60 degrees at ``mu`` 0.5); three
        fingertips 120 degrees apart, or one pad opposing another, give 0; a hand's three
        fingers on one face against its thumb give 0.5."""
        return self.squeeze_imbalance <= self.friction + _SQUEEZE_TOLERANCE

    @property
    def holds(self) -> bool:
        """True when the grasp resists its weight in every direction (margin >=
        :data:`MARGIN_TARGET`), as the feasibility tests made at construction found: no wrench
        space is built to say so."""
        return self._holds

    def to_dict(self) -> dict:
        """A JSON-ready record."""
        return {"friction": self.friction, "epsilon": self.epsilon,
                "force_closure": self.force_closure, "gravity_load": dict(self.gravity_load),
                "gravity_margin": dict(self.gravity_margin), "min_margin": self.min_margin,
                "contacts": self.contacts, "patches": self.patches, "radius": self.radius,
                "com_offset": self.com_offset, "squeeze_imbalance": self.squeeze_imbalance}


def _squeeze_imbalance(contacts: Contacts) -> float:
    """:attr:`GraspQuality.squeeze_imbalance` of a contact model: the length of the mean of
    the touching surfaces' unit mean inward normals; 1.0 without contacts."""
    surfaces = np.unique(contacts.surface)
    if not len(surfaces):
        return 1.0
    normals = np.array([contacts.normals[contacts.surface == s].mean(axis=0) for s in surfaces])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return float(np.linalg.norm(normals.sum(axis=0)) / len(surfaces))


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
    return grasps_quality(gripper, obj, np.asarray(T_object_gripper, dtype=float)[None],
                          np.asarray(q, dtype=float)[None], config, properties)[0]


def grasps_quality(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
                   q: np.ndarray, config: QualityConfig | None = None,
                   properties: ObjectProperties | None = None) -> list[GraspQuality]:
    """:func:`grasp_quality` of many grasps of one object: poses ``T_object_gripper``
    (G, 4, 4) and joints ``q`` (G, n_joints), their contact models built together
    (:func:`isf.quality.contacts.grasps_contacts`); the same records, except that grasps with
    the same contacts (positions and normals within 1e-12 m: a sampler that converges on one
    grasp many times repeats it to rounding) share one record, the first one's (the same
    object)."""
    config = QualityConfig() if config is None else config
    properties = object_properties(obj) if properties is None else properties
    contacts = grasps_contacts(gripper, obj, T_object_gripper, q, config.contact_model)
    records: list[GraspQuality] = []
    for k, first in enumerate(_first_with_same_contacts(contacts)):
        records.append(records[first] if first < k
                       else contacts_quality(contacts[k], properties, config))
    return records


def _first_with_same_contacts(contacts: list[Contacts]) -> np.ndarray:
    """For each contact model, the index of the first one (itself, or an earlier one that is
    the first of its kind) with the same contacts: the same contact surfaces and patches in
    the same order, and positions (metres) and normals within :data:`_SAME_CONTACTS`; (G,)."""
    first = np.arange(len(contacts))
    kinds: dict[tuple[bytes, bytes], list[int]] = {}
    for k, model in enumerate(contacts):
        kinds.setdefault((model.surface.tobytes(), model.patch.tobytes()), []).append(k)
    for members in kinds.values():
        if len(members) < 2:
            continue
        values = np.array([np.concatenate([contacts[k].points.ravel(),
                                           contacts[k].normals.ravel()]) for k in members])
        same = np.abs(values[:, None, :] - values[None, :, :]).max(axis=2, initial=0.0) \
            <= _SAME_CONTACTS
        members = np.array(members)
        for i in range(1, len(members)):
            earlier = np.flatnonzero(same[i, :i] & (first[members[:i]] == members[:i]))
            if earlier.size:
                first[members[i]] = members[earlier[0]]
    return first


@total_ordering
class _HigherMarginFirst:
    """A sort-key element that orders grasps by higher :attr:`GraspQuality.held_margin` first,
    deciding from bounds where it can: a held margin known to lie in ``[low, high)`` is below
    one known to be at least ``high`` (by :data:`_MARGIN_SEPARATION` at least). While two
    bounds do not settle it, the wider one is narrowed (:meth:`GraspQuality._refine_margin`, a
    feasibility test, down to :data:`_MARGIN_RESOLUTION`, then the value). The order is the
    one the values give."""

    __slots__ = ("quality",)
    __hash__ = None

    def __init__(self, quality: GraspQuality | None):
        self.quality = quality

    def _bounds(self) -> tuple[float, float, bool]:
        return (0.0, 0.0, True) if self.quality is None else self.quality._margin_bounds()

    def _compare(self, other: _HigherMarginFirst) -> int:
        """-1, 0 or 1 as this held margin is below, equal to or above the other's."""
        if self.quality is other.quality:  # one record (grasps with the same contacts)
            return 0
        while True:
            low, high, known = self._bounds()
            other_low, other_high, other_known = other._bounds()
            if known and other_known:
                return (low > other_low) - (low < other_low)
            if high + _MARGIN_SEPARATION <= other_low:
                return -1
            if other_high + _MARGIN_SEPARATION <= low:
                return 1
            if not known and (other_known or high - low >= other_high - other_low):
                self.quality._refine_margin()
            else:
                other.quality._refine_margin()

    def __eq__(self, other) -> bool:
        return self._compare(other) == 0

    def __lt__(self, other) -> bool:
        return self._compare(other) > 0


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
        return self.quality is other.quality or self._epsilon() == other._epsilon()

    def __lt__(self, other) -> bool:
        return self.quality is not other.quality and self._epsilon() > other._epsilon()


def expected_to_hold(quality: GraspQuality | None, *, closing_obstructed: bool = False) -> bool:
    """Whether the quality ranking expects a grasp to hold: its closing reaches the contact
    surfaces first (not ``closing_obstructed``), its squeeze is balanced
    (:attr:`GraspQuality.squeeze_balanced`) and it holds its weight in every gravity direction
    (:attr:`GraspQuality.holds`): the first tier of each of the first three criteria of
    :func:`quality_rank_key`. False without a quality record."""
    return (quality is not None and not closing_obstructed and quality.squeeze_balanced
            and quality.holds)


def quality_rank_key(quality: GraspQuality | None, mean_distance: float, *,
                     closing_obstructed: bool = False) -> tuple:
    """Sort key (lower first) of a grasp by its quality: a closing that reaches the contact
    surfaces first (``closing_obstructed`` False: no link that could stop a contact surface
    lies deeper in the object, :func:`isf.quality.closing.closing_obstructions`), then a balanced
    squeeze (:attr:`GraspQuality.squeeze_balanced`), then higher smallest gravity margin up to
    :data:`MARGIN_TARGET` (:attr:`GraspQuality.held_margin`: compared by bounds where they
    settle the order), then :attr:`GraspQuality.com_offset`, then higher epsilon (read only to
    break a tie of those before it), then its fitting error ``mean_distance`` (metres); a
    grasp without a quality record (None) comes after every grasp with one."""
    if quality is None:
        return (1, True, True, _HigherMarginFirst(None), 0.0, _HigherEpsilonFirst(None),
                mean_distance)
    return (0, bool(closing_obstructed), not quality.squeeze_balanced,
            _HigherMarginFirst(quality), quality.com_offset, _HigherEpsilonFirst(quality),
            mean_distance)
