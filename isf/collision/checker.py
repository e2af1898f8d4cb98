"""Collision checks of a fitted grasp: the whole gripper against the object and obstacle planes.

Every :class:`~isf.gripper.model.LinkGeometry` of the gripper (an *element*) is posed at
``T_object_gripper @ T_gripper_link(q)`` and compared with the object surface and with each
obstacle :class:`Plane`, all in the object frame, metres.

Penetration depth (how deep gripper geometry sits inside the object or an obstacle)
    * **Planes:** exact. A linear height attains its minimum over a mesh at a vertex, so the
      lowest convex-hull vertex of each element gives its depth below the plane.
    * **Gripper into object:** points sampled evenly (1 mm, at most 800) on each element's
      surface, plus its vertices, have the signed distance estimate ``max_k (p - o_k) . n_k``
      over their 6 nearest object points ``o_k`` with outward normals ``n_k``: a point is inside
      only when it lies below every nearby tangent plane, which keeps points beside a convex
      edge of the object outside (the price: a shallow penetration right at a concave crease of
      the object can read as none). This works for meshes and point clouds alike; a closed
      mesh object is resampled at 1 mm. An element whose samples lie on both sides crosses the
      object's surface and its depth is that of its deepest sample; one wholly inside has the
      depth of its last vertex.
    * **Object into gripper:** the object's points inside a closed element (exactly by its
      face planes when it is convex, else by the same tangent-plane estimate on the element's
      own surface samples) also count. This finds thin object features poking into the gripper
      between its samples.

    An element whose depth exceeds ``tolerance`` collides. The default 2 mm accepts the
    residual of a converged fit (pads sit on the object within a fraction of a millimetre),
    the discretisation of the object samples and the compliance of real finger pads, while a
    gripper part that truly intersects the object goes deeper than that.

How the samples are evaluated (what makes a check cheap)
    Each element's samples are grouped into about 24 *patches*. Elements whose bounding sphere
    lies wholly outside the object, and patches farther from the object's bounding box than
    their radius, are settled without samples; so, for a closed mesh object, are elements whose
    box and patches whose ball lie, with 2 mm to spare, in voxels certainly outside the mesh
    (``isf.collision.voxels``; samples that far outside the mesh are taken to be outside).
    The estimate is evaluated exactly at the other patch centres, but a patch wanted only for
    the clearance of a non-contact element only when it may hold a sample nearer to the object
    than the nearest evaluated centre of a non-contact element (by a lower bound of its centre's
    distance from the object's box and the voxels, less its radius). At every other sample it
    is predicted to first order (the centre's value plus the offset along the active tangent
    plane's normal), trusted to within 0.1 mm + 0.5 x the distance to the centre. Exactly
    evaluated are then only the samples whose bound could change a verdict (deeper than the
    tolerance), those that could be deeper than the deepest known sample of any element (a few
    per element and round), those that decide whether a non-contact element touches, and those
    that decide whether an element lies wholly inside. So the verdicts equal those of evaluating
    every sample whenever the prediction keeps its bound (a corpus of 720 planned and perturbed
    grasps agrees on all; ``bench/bench_collision.py``); the reported penetration is the deepest
    *evaluated* sample, within the prediction bound of the deepest of all samples (typically
    equal; tens of micrometres on curved contacts). A non-convex element screens many object
    points with a grid of its own estimate first.

    In detail: the first refinement round evaluates, per element, the 8 lowest-predicted
    samples that could decide the verdict, the 8 that could be deeper than the deepest known
    one and, while no obstacle plane touches, the 8 that could make a non-contact element touch;
    up to two later rounds evaluate all remaining verdict candidates of elements not yet deeper
    than the tolerance, and the 8 deepest-looking while the element's deepest value still grows;
    every round also evaluates the samples of an element none of whose samples (or settled
    patches) lies certainly outside that may lie outside. Ties go to the earlier sample.
    The whole body of a check, up to the exact distances to the object's mesh, is one compiled
    call (``isf.collision.kernel.check_elements``) on arrays prepared once per gripper and
    object; ``CollisionChecker.estimates`` counts the exact estimates made.

Clearance
    the smallest distance between a *non-contact* element and the object (contact elements are
    meant to touch), and from *every* element's hull to each obstacle plane; 0 when a
    non-contact element touches or penetrates the object, or any element an obstacle. It is
    measured both ways with exact point distances. The 48 samples of the non-contact elements
    tested nearest to the object point nearest their patch's centre are the candidates; each
    gets the distance to its nearest object sample, and the 3 nearest of them the distance to
    the object's mesh (coal; none for a point cloud). Then, for the two elements of the lowest
    indices among the candidates, the 4 object samples nearest the element's best candidate
    get their distance to the element's triangles. It never reads below
    the true distance and exceeds it by at most about half the sample spacing of the nearest
    element (0.5 mm on elements up to 8 cm^2, more on larger ones, e.g. 2 mm on a 32 x 64 x 40 mm
    palm) plus half the object's point spacing for a point cloud.
    *Contact elements* are those the contact-surface points of their link lie on (or, when none
    does, every element of that link).
"""

from __future__ import annotations

import logging
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import coal
import numpy as np

from ..compiled.kernels import kernel
from ..exceptions import GripperDescriptionError, InvalidInputError
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..search.kdtree import KDTree
from ._elements import Element, even_samples, point_triangle_distance
from .kernel import (
    PREDICTION_ERROR,
    PREDICTION_SLOPE,
    Elements,
    Interiors,
    Obstacles,
    Patches,
    Probes,
    Surface,
    check_elements,
    reverse_clearance,
)
from .surface_distance import NEIGHBOURS, TangentPlanes, closed_mesh, mesh_memo
from .voxels import SurfaceVoxels, kernel_arrays

__all__ = ["CollisionChecker", "CollisionReport", "HiddenRegion", "Plane"]

logger = logging.getLogger(__name__)

_OBJECT_SPACING = 0.001  # resampling of a closed mesh object, m
_MAX_OBJECT_SAMPLES = 50000
_ON_SURFACE = 1e-6  # a contact point this close to an element lies on it, m
_CLEARANCE_EXACT = 3  # of the clearance candidates, how many get the exact distance to a mesh object (coal)
_REVERSE_PROBES = 4  # object samples whose distance to the nearest-looking elements is measured


@kernel
def _rigid(T):
    """Is the finite 4x4 ``T`` a rigid transform: rotation orthonormal to 1e-6, last row
    ``[0 0 0 1]`` to 1e-12?"""
    for i in range(3):
        for j in range(3):
            dot = T[0, i] * T[0, j] + T[1, i] * T[1, j] + T[2, i] * T[2, j]
            if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                return False
    return (abs(T[3, 0]) <= 1e-12 and abs(T[3, 1]) <= 1e-12 and abs(T[3, 2]) <= 1e-12
            and abs(T[3, 3] - 1.0) <= 1e-12)


def checked_state(gripper: Gripper, T_object_gripper, q) -> tuple[np.ndarray, np.ndarray]:
    """A gripper state as the compiled checks and the repair take it: ``T_object_gripper`` as a
    C-ordered float copy (4, 4) and ``q`` as floats (n_joints,).

    Raises:
        InvalidInputError: ``T_object_gripper`` is not a finite rigid transform, or ``q`` does not
            hold ``n_joints`` finite values (non-finite input would reach the compiled kernels).
    """
    T = np.array(T_object_gripper, dtype=float, order="C")  # a writeable copy: one compiled type
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InvalidInputError(f"T_object_gripper must be a finite 4x4 homogeneous transform, "
                                f"got shape {T.shape}; pass the fitted palm pose")
    if not _rigid(T):
        raise InvalidInputError("T_object_gripper is not a rigid transform (rotation not "
                                "orthonormal or last row not [0 0 0 1]); re-orthonormalise it")
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (gripper.n_joints,) or not np.isfinite(q).all():
        raise InvalidInputError(f"q must hold {gripper.n_joints} finite joint values, got {q.shape}")
    return T, q


def mesh_bvh(vertices: np.ndarray, faces: np.ndarray) -> coal.BVHModelOBBRSS:
    """A coal BVH of a triangle mesh: vertices (V, 3), faces (F, 3)."""
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(faces), len(vertices))
    model.addVertices(np.ascontiguousarray(vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(faces, dtype=np.int64))
    model.endModel()
    return model


def mesh_distances(bvh: coal.BVHModelOBBRSS, points: np.ndarray) -> np.ndarray:
    """Exact distance (m) of each point (P, 3), mesh frame, from the triangle mesh of ``bvh``
    (:func:`mesh_bvh`), by coal, (P,)."""
    point, at, identity = coal.Sphere(0.0), coal.Transform3s(), coal.Transform3s()
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    out = np.empty(len(points))
    for k, p in enumerate(np.asarray(points, dtype=float)):
        at.setTranslation(p)
        result.clear()
        out[k] = coal.distance(point, at, bvh, identity, request, result)
    return out


def object_bvh(obj: ObjectSurface) -> coal.BVHModelOBBRSS:
    """The coal BVH of a mesh object's triangles, built once per mesh (see
    :func:`isf.collision.surface_distance.mesh_memo`)."""
    memo = mesh_memo(obj)
    if "bvh" not in memo:
        memo["bvh"] = mesh_bvh(np.asarray(obj.mesh_vertices, float),
                               np.asarray(obj.mesh_faces, np.int64))
    return memo["bvh"]


def object_voxels(obj: ObjectSurface) -> SurfaceVoxels | None:
    """The voxels around a closed, outward mesh object (None for any other), built once per
    mesh (see :func:`isf.collision.surface_distance.mesh_memo`)."""
    if closed_mesh(obj) is None:
        return None
    memo = mesh_memo(obj)
    if "voxels" not in memo:
        memo["voxels"] = SurfaceVoxels(obj.mesh_vertices, obj.mesh_faces)
    return memo["voxels"]


@dataclass(frozen=True, eq=False)
class Plane:
    """An obstacle half-space in the object frame: points x with ``normal . x < offset`` are inside.

    Attributes:
        normal: unit normal pointing out of the obstacle, shape (3,) (normalised on creation).
        offset: plane offset along ``normal``, metres.
        name: the name reported for collisions with it.
    """

    normal: np.ndarray
    offset: float
    name: str = "plane"

    def __post_init__(self) -> None:
        n = np.asarray(self.normal, dtype=float).reshape(-1)
        norm = float(np.linalg.norm(n)) if n.shape == (3,) else 0.0
        if not (np.isfinite(norm) and norm > 1e-12):
            raise InvalidInputError(f"plane {self.name!r}: normal must be a finite non-zero 3-vector, "
                                    f"got {self.normal!r}; pass e.g. (0, 0, 1)")
        if not np.isfinite(self.offset):
            raise InvalidInputError(f"plane {self.name!r}: offset must be finite metres, got {self.offset!r}")
        n = n / norm
        n.flags.writeable = False
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "offset", float(self.offset) / norm)

    @classmethod
    def table(cls, z: float, name: str = "table") -> Plane:
        """A support plane ``z = const`` under the object: the obstacle is everything below ``z``."""
        return cls(np.array([0.0, 0.0, 1.0]), float(z), name)

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed height of points (M, 3) above the plane, metres (negative inside the obstacle)."""
        return points @ self.normal - self.offset


class HiddenRegion(Protocol):
    """A region of the object frame the gripper must not enter, known only by how deep points
    lie inside it (e.g. :class:`isf.scene.UnseenSpace`, the space behind a camera's view)."""

    name: str

    def depth_inside(self, points: np.ndarray) -> np.ndarray:
        """Depth of each point (M, 3) inside the region, metres (M,); 0 outside."""

    def way_out(self, points: np.ndarray) -> np.ndarray:
        """Unit directions (M, 3) along which points (M, 3) inside the region leave it
        (the collision repair pushes links that way)."""


@dataclass(frozen=True)
class CollisionReport:
    """The verdict of one collision check.

    Attributes:
        collision_free: no element penetrates the object or an obstacle deeper than the tolerance.
        penetration: deepest penetration of any element into the object or an obstacle, metres (0 if none).
        clearance: distance from the non-contact elements to the object and from all elements to
            the obstacle planes, metres; 0 when touching or penetrating (see the module docs).
        colliding_links: links with an element deeper than the tolerance, in the order of
            ``gripper.geometries``.
        obstacle: ``"object"``, the plane's name or the hidden region's name for the deepest
            violation; None when collision-free.
        link_depths: the deepest penetration of each checked link's elements into the object
            or an obstacle, metres (0 where none), by link name, in the order of
            ``gripper.geometries``: the deepest evaluated sample of each element, as
            :attr:`penetration` is for the whole gripper (see the module docs).
    """

    collision_free: bool
    penetration: float
    clearance: float
    colliding_links: tuple[str, ...]
    obstacle: str | None
    link_depths: Mapping[str, float] = field(default_factory=dict)


class CollisionChecker:
    """Checks posed grippers against one object and fixed obstacle planes.

    Build it once per (gripper, object) pair; :meth:`check` is then cheap (what it derives
    from the gripper and from a mesh object is kept while they live, so building another for
    the same gripper or object is cheap too), and
    :meth:`check_many` checks a batch of poses (one :meth:`check` each).

    Args:
        gripper: the gripper; every one of its ``geometries`` is checked.
        obj: the object surface (a mesh or a point cloud with outward normals), object frame.
        obstacles: obstacle half-spaces in the object frame, e.g. ``[Plane.table(z)]``.
        tolerance: penetration depth tolerated before an element collides, metres (>= 0).
        hidden: a region the gripper must not enter (:class:`HiddenRegion`), e.g. a scene's
            unseen space; an element's depth in it is the deepest of its surface samples (the
            samples of the object check, vertices included). A non-contact element inside it
            makes the clearance 0.

    Raises:
        InvalidInputError: a negative or non-finite tolerance, or an obstacle that is not a Plane.
        GripperDescriptionError: the gripper has no geometry, or a geometry names an unknown link.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, *, obstacles: Sequence[Plane] = (),
                 tolerance: float = 0.002, hidden: HiddenRegion | None = None):
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(tolerance) and tolerance >= 0):
            raise InvalidInputError(f"collision tolerance must be a finite depth >= 0 in metres, "
                                    f"got {tolerance!r}; the default is 0.002")
        self.obstacles = tuple(obstacles)
        for plane in self.obstacles:
            if not isinstance(plane, Plane):
                raise InvalidInputError(f"obstacles must be isf.collision.checker.Plane objects, got "
                                        f"{type(plane).__name__}; use e.g. Plane.table(z)")
        if not gripper.geometries:
            raise GripperDescriptionError(gripper.name, [
                "it has no link geometry to check for collisions; give its links <collision> elements"])
        self.gripper, self.object, self.tolerance = gripper, obj, float(tolerance)
        links = list(dict.fromkeys(g.link for g in gripper.geometries))
        missing = [link for link in links if not gripper.model.existFrame(link)]
        if missing:
            raise GripperDescriptionError(gripper.name, [
                f"a geometry belongs to link {link!r}, which the model lacks; fix its link name"
                for link in missing])
        self._frame_ids = np.array([gripper.model.getFrameId(link) for link in links])
        self.hidden = hidden
        self._obstacle_names = [p.name for p in self.obstacles] + ["object"] + (
            [] if hidden is None else [hidden.name])
        self._elements, packed, state = _prepared(gripper, links)
        self._links = links
        self._element_link = np.array([e.frame for e in self._elements], dtype=np.int64)
        if hidden is not None:
            self._hidden_samples = _HiddenSamples.of(packed)
        self._triangles, self._triangle_start = packed["_triangles"], packed["_triangle_start"]
        self._surface = _object_surface(obj, state)
        self._points = np.asarray(obj.points, dtype=float)  # probes for object points inside elements
        self._lo, self._hi = self._surface.points.min(axis=0), self._surface.points.max(axis=0)
        self._mesh = object_bvh(obj) if obj.is_mesh else None
        self._voxels = object_voxels(obj)
        # Distance from the object's surface to its nearest sample, at most (a generous guess:
        # random samples leave gaps a few spacings wide; 0 for a bare point cloud).
        self._cover = 3.0 * self._surface.spacing if obj.is_mesh else 0.0
        self._kernel_args = (
            Obstacles(np.array([p.normal for p in self.obstacles]).reshape(-1, 3),
                      np.array([p.offset for p in self.obstacles], dtype=float)),
            Elements(**{name: packed["_" + name] for name in Elements._fields}),
            Patches(**{name: packed["_" + name] for name in Patches._fields}),
            Surface(self._surface.points, self._surface.normals, self._surface.tree.tree, self._lo,
                    self._hi, self._cover, min(NEIGHBOURS, len(self._surface.points))),
            _probe_grid(self._points),
            kernel_arrays(self._voxels),
            packed["interiors"])
        self.estimates = 0
        """Exact tangent-plane estimates of the object's surface made by the checks so far (a
        cost diagnostic)."""

    # ------------------------------------------------------------------- check
    def check(self, T_object_gripper: np.ndarray, q: np.ndarray) -> CollisionReport:
        """Check the gripper at palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,).

        Raises:
            InvalidInputError: ``T_object_gripper`` is not a rigid transform or ``q`` has the wrong size.
        """
        T, q = checked_state(self.gripper, T_object_gripper, q)
        links = self.gripper.frame_kinematics_many(q[None], self._frame_ids)
        poses, depth, where, clearance, candidates, owner, nearest, estimates = check_elements(
            T, links.rotations[0], links.positions[0], self.tolerance, *self._kernel_args)
        self.estimates += estimates
        if clearance > 0.0 and len(candidates):
            clearance = min(clearance, self._clearance_of(candidates, owner, nearest, poses))
        if self.hidden is not None:
            depth, where, clearance = self._hidden_depths(poses, depth, where, clearance)
        colliding = [self._elements[i].link for i in np.flatnonzero(depth > self.tolerance)]
        worst = int(np.argmax(depth))
        free = not colliding
        link_depths = np.zeros(len(self._links))
        np.maximum.at(link_depths, self._element_link, depth)
        return CollisionReport(
            collision_free=free, penetration=float(depth[worst]), clearance=float(clearance),
            colliding_links=tuple(dict.fromkeys(colliding)),
            obstacle=None if free else self._obstacle_names[where[worst]],
            link_depths=dict(zip(self._links, link_depths.tolist())),
        )

    def check_many(self, T_object_gripper: np.ndarray, q: np.ndarray) -> list[CollisionReport]:
        """:meth:`check` of B poses (B, 4, 4) with joints (B, n_joints), in order.

        Raises:
            InvalidInputError: a pose is not a rigid transform or the joints have the wrong shape.
        """
        T = np.asarray(T_object_gripper, dtype=float)
        q = np.asarray(q, dtype=float)
        if T.ndim != 3 or q.ndim != 2 or len(T) != len(q):
            raise InvalidInputError(f"check_many takes poses (B, 4, 4) and joints (B, n_joints), got "
                                    f"{T.shape} and {q.shape}; stack one pose and joint vector per grasp")
        return [self.check(t, j) for t, j in zip(T, q)]

    def _hidden_depths(self, poses: np.ndarray, depth: np.ndarray, where: np.ndarray,
                       clearance: float) -> tuple[np.ndarray, np.ndarray, float]:
        """The elements' depths (E,) and obstacles (E,) with the hidden region's added, and the
        clearance (0 when a non-contact element enters the region)."""
        samples = self._hidden_samples
        R, t = poses[samples.owner, :3, :3], poses[samples.owner, :3, 3]
        points = np.einsum("sij,sj->si", R, samples.points) + t
        inside = np.maximum.reduceat(self.hidden.depth_inside(points), samples.starts)
        deeper = inside > depth
        if (inside[samples.non_contact] > 0).any():
            clearance = 0.0
        return (np.where(deeper, inside, depth),
                np.where(deeper, len(self._obstacle_names) - 1, where), clearance)

    # ------------------------------------------------------------------- clearance
    def _clearance_of(self, points: np.ndarray, owner: np.ndarray, nearest: np.ndarray,
                      poses: np.ndarray) -> float:
        """Smallest distance between the elements and the object, metres, measured from samples
        ``points`` (M, 3) of elements ``owner`` (M,) that lie nearest the object (``nearest``:
        their distances to the nearest object point).

        Both ways, each an exact point distance: from the few samples nearest the object's samples
        to the object's mesh (coal; to the nearest object sample for a point cloud), and from the
        object samples nearest the best of those to the triangles of their elements
        (:func:`isf.collision.kernel.reverse_clearance`).
        """
        measured = nearest.copy()
        if self._mesh is not None:
            exact = np.argsort(nearest, kind="stable")[:_CLEARANCE_EXACT]
            measured[exact] = mesh_distances(self._mesh, points[exact])
        return reverse_clearance(measured, points, owner, poses, self._triangles, self._triangle_start,
                                 self._surface.points, self._surface.tree.tree,
                                 min(_REVERSE_PROBES, len(self._surface.points)))


# ---------------------------------------------------------------------- set-up
class _HiddenSamples(NamedTuple):
    """Every element's surface samples, element by element, for the hidden region's depths."""

    points: np.ndarray  # (S, 3) link frames: the checks' own samples (Patches.samples)
    owner: np.ndarray  # (S,) element of each sample
    starts: np.ndarray  # (E,) first sample of each element
    non_contact: np.ndarray  # (E,) bool: the element is not a contact element

    @classmethod
    def of(cls, packed: dict) -> _HiddenSamples:
        """From :func:`_packed`'s arrays, whose elements are contiguous runs of patches."""
        samples = packed["_samples"]
        starts = packed["_patch_start"][packed["_element_patches"][:-1]]
        counts = np.diff(np.r_[starts, len(samples)])
        return cls(samples, np.repeat(np.arange(len(starts)), counts), starts,
                   ~packed["_contact"])


class _Prepared(NamedTuple):
    """A gripper's prepared elements (:func:`_prepared`), with a weak reference to the gripper."""

    gripper: weakref.ref
    elements: list[Element]
    packed: dict
    state: dict


_PREPARED: dict[int, _Prepared] = {}


def _prepared(gripper: Gripper, links: list[str]) -> tuple[list[Element], dict, dict]:
    """The gripper's elements (contact ones marked), their arrays stacked for vectorised checks
    (:func:`_packed`) and the state of the random generator after sampling them; built once
    per gripper (its parts are treated as immutable) and kept while it lives."""
    entry = _PREPARED.get(id(gripper))
    if entry is not None and entry.gripper() is gripper:
        return entry.elements, entry.packed, entry.state
    rng = np.random.default_rng(0)
    elements = [Element(g, links.index(g.link), rng) for g in gripper.geometries]
    _mark_contact_elements(elements, gripper)
    state = rng.bit_generator.state
    entry = _Prepared(weakref.ref(gripper), elements, _packed(elements), state)
    _PREPARED[id(gripper)] = entry
    weakref.finalize(gripper, _PREPARED.pop, id(gripper), None)
    return entry.elements, entry.packed, entry.state


def _mark_contact_elements(elements: list[Element], gripper: Gripper) -> None:
    for link in dict.fromkeys(s.link for s in gripper.surfaces):
        points = np.concatenate([s.points for s in gripper.surfaces if s.link == link])
        mine = [e for e in elements if e.link == link]
        probe = points[:: max(1, len(points) // 32)].astype(float)
        hits = [e for e in mine
                if point_triangle_distance(probe, e.mesh.triangles).max() <= _ON_SURFACE]
        for e in hits or mine:
            e.contact = True


def _object_surface(obj: ObjectSurface, state: dict) -> TangentPlanes:
    """The tangent planes of the object's points plus, for a closed, outward mesh object, dense
    samples of its mesh drawn from a generator in ``state``; built once per mesh, points and
    state (see :func:`isf.collision.surface_distance.mesh_memo`)."""
    mesh = closed_mesh(obj)
    if mesh is None:
        logger.debug("%s: not a closed, outward mesh; collision checks use its points", obj.name)
        return TangentPlanes(obj.points, obj.normals, obj.spacing)
    spacing = min(obj.spacing, _OBJECT_SPACING)
    key = ("surface", spacing, repr(state), hash(obj.points.tobytes()), hash(obj.normals.tobytes()))
    memo = mesh_memo(obj)
    if key not in memo:
        rng = np.random.default_rng(0)
        rng.bit_generator.state = state
        points, normals = even_samples(mesh, spacing, _MAX_OBJECT_SAMPLES, rng)
        memo[key] = TangentPlanes(np.concatenate([obj.points, points]),
                                  np.concatenate([obj.normals, normals]),
                                  float(np.sqrt(mesh.area / len(points))))
    return memo[key]


def _probe_grid(points: np.ndarray, cells: int = 32) -> Probes:
    """The object points (M, 3) in a grid of cubic cells, about ``cells`` along the box's longest
    side."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    cell = max(float((hi - lo).max()) / cells, 1e-3)
    shape = np.floor((hi - lo) / cell).astype(np.int64) + 1
    key = np.minimum(np.floor((points - lo) / cell).astype(np.int64), shape - 1)
    index = (key[:, 0] * shape[1] + key[:, 1]) * shape[2] + key[:, 2]
    order = np.argsort(index, kind="stable")
    start = np.r_[0, np.cumsum(np.bincount(index, minlength=int(np.prod(shape))))]
    return Probes(np.ascontiguousarray(points[order]), start, lo, cell, shape)


def _stacked(parts: list[np.ndarray], dtype=float) -> tuple[np.ndarray, np.ndarray]:
    """The arrays ``parts`` stacked along their first axis, and where each starts (len + 1,)."""
    return (np.ascontiguousarray(np.concatenate(parts), dtype=dtype),
            np.r_[0, np.cumsum([len(x) for x in parts])])


def _interiors(els: list[Element]) -> Interiors:
    """The insides of the closed non-convex elements stacked (empty for the others): hull
    planes, grids (values raveled, with their shapes, corners and spacings) and surfaces with
    their k-d trees (indices within each element's part)."""
    hulls = [e.hull_planes if e.surface is not None and e.hull_planes is not None
             else np.empty((0, 4)) for e in els]
    fields = [e.field if e.surface is not None else None for e in els]
    surfaces = [e.surface for e in els]
    hull_planes, hull_start = _stacked(hulls)
    field, field_start = _stacked([np.ravel(f.values) if f is not None else np.empty(0) for f in fields])
    inner_points, inner_start = _stacked(
        [s.points if s is not None else np.empty((0, 3)) for s in surfaces])
    inner_normals, _ = _stacked([s.normals if s is not None else np.empty((0, 3)) for s in surfaces])
    trees = [s.tree.tree.kd if s is not None else None for s in surfaces]

    empty = {"points": np.empty((0, 3)), "split": np.empty(0)}

    def stacked_field(name: str) -> np.ndarray:
        part = empty.get(name, np.empty(0, np.int64))
        array, _ = _stacked([getattr(t, name) if t else part for t in trees], part.dtype)
        return array

    tree = KDTree(**{name: stacked_field(name) for name in KDTree._fields})
    _, node_start = _stacked([t.start if t else np.empty(0, np.int64) for t in trees], np.int64)
    return Interiors(
        hull_planes=hull_planes, hull_start=hull_start, field=field, field_start=field_start,
        field_shape=np.array([f.values.shape if f is not None else (0, 0, 0) for f in fields]),
        field_lo=np.array([f.lo if f is not None else np.zeros(3) for f in fields]),
        field_h=np.array([f.h if f is not None else 1.0 for f in fields]),
        inner_start=inner_start, node_start=node_start, inner_points=inner_points,
        inner_normals=inner_normals, tree=tree)


def _packed(els: list[Element]) -> dict[str, np.ndarray]:
    """Per-element arrays stacked for the compiled checks (:func:`isf.collision.kernel.check_elements`
    describes them), samples grouped by patch; the elements' triangles (link frame) stacked.

    Every patch is a contiguous run of rows with its centre first; elements are contiguous
    runs of patches.
    """
    planes = [e.planes if e.planes is not None else np.empty((0, 4)) for e in els]
    out = {"_frames": np.array([e.frame for e in els]),
           "_contact": np.array([e.contact for e in els], dtype=bool),
           "_kind": np.array([0 if not e.closed else 1 if e.planes is not None else 2 for e in els]),
           "_bounds": np.array([e.bounds for e in els]),
           "_planes": np.ascontiguousarray(np.concatenate(planes), dtype=float),
           "_plane_start": np.r_[0, np.cumsum([len(x) for x in planes])],
           "_hull": np.concatenate([e.hull for e in els]),
           "_hull_start": np.r_[0, np.cumsum([len(e.hull) for e in els])],
           "_sphere": np.array([e.centre for e in els]),
           "_radius": np.array([e.radius for e in els]),
           "_triangles": np.ascontiguousarray(np.concatenate([e.mesh.triangles for e in els]), dtype=float),
           "_triangle_start": np.r_[0, np.cumsum([len(e.mesh.faces) for e in els])]}
    out["interiors"] = _interiors(els)
    samples, offsets, starts, sizes, last, rows = [], [], [], [], [], 0
    for e in els:
        is_centre = np.zeros(len(e.samples), dtype=bool)
        is_centre[e.centres] = True
        order = np.lexsort((~is_centre, e.parent))
        parent = e.parent[order]
        first = np.flatnonzero(np.r_[True, parent[1:] != parent[:-1]])
        samples.append(e.samples[order])
        offsets.append(e.samples[order] - e.samples[e.centres[parent]])
        starts.append(rows + first)
        sizes.append(np.diff(np.r_[first, len(order)]))
        vertex = np.flatnonzero(order == len(e.samples) - 1)[0]
        last.append(int(np.searchsorted(first, vertex, "right") - 1))
        rows += len(order)
    offsets = np.concatenate(offsets)
    reach = np.linalg.norm(offsets, axis=1)
    patch_start = np.concatenate(starts)
    margin = PREDICTION_ERROR + PREDICTION_SLOPE * reach
    margin[patch_start] = 0.0  # the centres
    patch_radius = np.maximum.reduceat(reach, patch_start)
    element_patches = np.r_[0, np.cumsum([len(x) for x in starts])]
    out.update({
        "_samples": np.concatenate(samples), "_offsets": offsets, "_margin": margin,
        "_patch_start": patch_start, "_patch_size": np.concatenate(sizes),
        "_patch_radius": patch_radius,
        "_patch_margin": PREDICTION_ERROR + PREDICTION_SLOPE * patch_radius,
        "_box_lo": np.minimum.reduceat(offsets, patch_start),
        "_box_hi": np.maximum.reduceat(offsets, patch_start),
        "_element_patches": element_patches,
        "_last_patch": element_patches[:-1] + np.array(last),  # patch of the last vertex
    })
    return out
