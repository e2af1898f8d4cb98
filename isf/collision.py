"""Collision checks of a fitted grasp: the whole gripper against the object and obstacle planes.

Every :class:`~isf.gripper.LinkGeometry` of the gripper (an *element*) is posed at
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
    (``isf.collision_voxels``; samples that far outside the mesh are taken to be outside).
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

Clearance
    the smallest distance between a *non-contact* element and the object (contact elements are
    meant to touch), and from *every* element's hull to each obstacle plane; 0 when a
    non-contact element touches or penetrates the object, or any element an obstacle. It is
    measured both ways with exact point distances: from the element samples nearest the
    object's samples to the object's mesh (coal; to the nearest object point for a point cloud),
    and from the object samples nearest those to the element's triangles. It never reads below
    the true distance and exceeds it by at most about half the sample spacing of the nearest
    element (0.5 mm on elements up to 8 cm^2, more on larger ones, e.g. 2 mm on a 32 x 64 x 40 mm
    palm) plus half the object's point spacing for a point cloud.
    *Contact elements* are those the contact-surface points of their link lie on (or, when none
    does, every element of that link).
"""

from __future__ import annotations

import logging
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from .collision_elements import Element, bvh, even_samples, point_triangle_distance
from .collision_surface import TangentPlanes, closed_mesh, mesh_memo
from .collision_voxels import SurfaceVoxels
from .exceptions import GripperDescriptionError, InvalidInputError
from .gripper import Gripper
from .object_surface import ObjectSurface

__all__ = ["CollisionChecker", "CollisionReport", "Plane"]

logger = logging.getLogger(__name__)

_OBJECT_SPACING = 0.001  # resampling of a closed mesh object, m
_MAX_OBJECT_SAMPLES = 50000
_ON_SURFACE = 1e-6  # a contact point this close to an element lies on it, m
# First-order prediction of the signed distance at a sample from its patch centre is trusted to
# within _PREDICTION_ERROR + _PREDICTION_SLOPE * (distance to the centre).
_PREDICTION_ERROR = 1e-4  # m
_PREDICTION_SLOPE = 0.5
_DEEPEST_CANDIDATES = 8  # samples evaluated exactly to find an element's deepest one
_CLEARANCE_CANDIDATES = 48  # nearest-looking samples whose object distance is measured
_CLEARANCE_EXACT = 3  # of those, how many get the exact distance to a mesh object (coal)
_DEPTH_RESOLUTION = 5e-5  # deeper-looking samples than the deepest evaluated get evaluated, m
_CLEARANCE_PATCHES = 2  # patches nearest the object whose samples are candidates for clearance
_REVERSE_PROBES = 4  # object samples whose distance to the nearest-looking elements is measured
_CULL_MARGIN = 5e-4  # an element whose bounding sphere is this far outside the object is outside, m
_VOXEL_MARGIN = 2e-3  # a box this far inside voxels outside a mesh object is outside it, m


def object_bvh(obj: ObjectSurface) -> coal.BVHModelOBBRSS:
    """The coal BVH of a mesh object's triangles, built once per mesh (0.7 s for the 85k
    triangles of the benchmark bunny; see :func:`isf.collision_surface.mesh_memo`)."""
    memo = mesh_memo(obj)
    if "bvh" not in memo:
        memo["bvh"] = bvh(np.asarray(obj.mesh_vertices, float), np.asarray(obj.mesh_faces, np.int64))
    return memo["bvh"]


def object_voxels(obj: ObjectSurface) -> SurfaceVoxels | None:
    """The voxels around a closed, outward mesh object (None for any other), built once per
    mesh (see :func:`isf.collision_surface.mesh_memo`)."""
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
        obstacle: ``"object"`` or the plane's name for the deepest violation; None when collision-free.
    """

    collision_free: bool
    penetration: float
    clearance: float
    colliding_links: tuple[str, ...]
    obstacle: str | None


class CollisionChecker:
    """Checks posed grippers against one object and fixed obstacle planes.

    Build it once per (gripper, object) pair; :meth:`check` is then cheap (what it derives
    from the gripper and from a mesh object is kept while they live, so building another for
    the same gripper or object is cheap too), and
    :meth:`check_many` checks a batch of poses (for now one :meth:`check` each; no work is
    shared across grasps yet).

    Args:
        gripper: the gripper; every one of its ``geometries`` is checked.
        obj: the object surface (a mesh or a point cloud with outward normals), object frame.
        obstacles: obstacle half-spaces in the object frame, e.g. ``[Plane.table(z)]``.
        tolerance: penetration depth tolerated before an element collides, metres (>= 0).

    Raises:
        InvalidInputError: a negative or non-finite tolerance, or an obstacle that is not a Plane.
        GripperDescriptionError: the gripper has no geometry, or a geometry names an unknown link.
    """

    def __init__(self, gripper: Gripper, obj: ObjectSurface, *, obstacles: Sequence[Plane] = (),
                 tolerance: float = 0.002):
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(tolerance) and tolerance >= 0):
            raise InvalidInputError(f"collision tolerance must be a finite depth >= 0 in metres, "
                                    f"got {tolerance!r}; the default is 0.002")
        self.obstacles = tuple(obstacles)
        for plane in self.obstacles:
            if not isinstance(plane, Plane):
                raise InvalidInputError(f"obstacles must be isf.collision.Plane objects, got "
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
        self._links = links
        self._frame_ids = [gripper.model.getFrameId(link) for link in links]
        self._data = gripper.model.createData()
        self._elements, packed, state = _prepared(gripper, links)
        vars(self).update(packed)
        self._surface = _object_surface(obj, state)
        self._points = np.asarray(obj.points, dtype=float)  # probes for object points inside elements
        self._lo, self._hi = self._surface.points.min(axis=0), self._surface.points.max(axis=0)
        self._mesh = object_bvh(obj) if obj.is_mesh else None
        self._voxels = object_voxels(obj)
        # Distance from the object's surface to its nearest sample, at most (a generous guess:
        # random samples leave gaps a few spacings wide; 0 for a bare point cloud).
        self._cover = 3.0 * self._surface.spacing if obj.is_mesh else 0.0
        self._point = coal.Sphere(0.0)
        self._identity = coal.Transform3s()
        self._distance_request = coal.DistanceRequest()

    # ------------------------------------------------------------------- check
    def _link_poses(self, T: np.ndarray, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.gripper.model, self._data, q)
        return np.array([T @ self._data.oMf[fid].homogeneous for fid in self._frame_ids])

    def _check_inputs(self, T_object_gripper, q) -> tuple[np.ndarray, np.ndarray]:
        T = np.asarray(T_object_gripper, dtype=float)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise InvalidInputError(f"T_object_gripper must be a finite 4x4 homogeneous transform, "
                                    f"got shape {T.shape}; pass the fitted palm pose")
        R = T[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12:
            raise InvalidInputError("T_object_gripper is not a rigid transform (rotation not "
                                    "orthonormal or last row not [0 0 0 1]); re-orthonormalise it")
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.gripper.n_joints,) or not np.isfinite(q).all():
            raise InvalidInputError(f"q must hold {self.gripper.n_joints} finite joint values, got {q.shape}")
        return T, q

    def check(self, T_object_gripper: np.ndarray, q: np.ndarray) -> CollisionReport:
        """Check the gripper at palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,).

        Raises:
            InvalidInputError: ``T_object_gripper`` is not a rigid transform or ``q`` has the wrong size.
        """
        T, q = self._check_inputs(T_object_gripper, q)
        return _Check(self, self._link_poses(T, q)[self._frames]).report()

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

    # ---------------------------------------------------- helpers of _Check
    def _object_inside(self, elements: list[int], poses: np.ndarray) -> dict[int, float]:
        """Deepest object point inside each of the closed ``elements`` posed at ``poses`` (E, 4, 4)."""
        out = {}
        for i in elements:
            e = self._elements[i]
            if e.closed:
                d = e.object_depth(self._points, poses[i], self.tolerance)
                if d > 0.0:
                    out[i] = d
        return out

    def _point_distance(self, point: np.ndarray, geometry, pose: coal.Transform3s) -> float:
        """Exact distance from a point (3,) to a coal geometry posed at ``pose``, metres."""
        return coal.distance(self._point, coal.Transform3s(np.eye(3), point), geometry, pose,
                             self._distance_request, coal.DistanceResult())

    def _clearance_of(self, points: np.ndarray, owner: np.ndarray, poses: np.ndarray) -> float:
        """Smallest distance between the elements and the object, metres, measured from samples
        ``points`` (M, 3) of elements ``owner`` (M,) that lie nearest the object.

        Both ways, each an exact point distance: from the few samples nearest the object's samples
        to the object's mesh (coal; to the nearest object sample for a point cloud), and from the
        object samples nearest the best of those to the triangles of its element and of the
        runner-up element.
        """
        k = min(_REVERSE_PROBES, len(self._surface.points))
        nearest, idx = self._surface.tree.query_k(points, k)
        nearest = nearest[:, 0]
        measured = nearest.copy()
        if self._mesh is not None:
            for j in np.argsort(nearest)[:_CLEARANCE_EXACT]:
                measured[j] = self._point_distance(points[j], self._mesh, self._identity)
        order = np.argsort(measured)
        best = float(measured[order[0]])
        for j in order[np.unique(owner[order], return_index=True)[1]][:2]:
            e = int(owner[j])
            pose = coal.Transform3s(poses[e, :3, :3], poses[e, :3, 3])
            for probe in self._surface.points[idx[j]]:
                best = min(best, self._point_distance(probe, self._elements[e].bvh, pose))
        return max(best, 0.0)


# ---------------------------------------------------------------------- set-up
_PREPARED: dict[int, tuple[weakref.ref, list[Element], dict, dict]] = {}


def _prepared(gripper: Gripper, links: list[str]) -> tuple[list[Element], dict, dict]:
    """The gripper's elements (contact ones marked), their arrays stacked for vectorised checks
    (:func:`_packed`) and the state of the random generator after sampling them; built once
    per gripper (its parts are treated as immutable) and kept while it lives."""
    entry = _PREPARED.get(id(gripper))
    if entry is not None and entry[0]() is gripper:
        return entry[1], entry[2], entry[3]
    rng = np.random.default_rng(0)
    elements = [Element(g, links.index(g.link), rng) for g in gripper.geometries]
    _mark_contact_elements(elements, gripper)
    state = rng.bit_generator.state
    _PREPARED[id(gripper)] = (weakref.ref(gripper), elements, _packed(elements), state)
    weakref.finalize(gripper, _PREPARED.pop, id(gripper), None)
    return _PREPARED[id(gripper)][1:]


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
    state (see :func:`isf.collision_surface.mesh_memo`)."""
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


def _packed(els: list[Element]) -> dict[str, np.ndarray]:
    """Per-element arrays stacked for vectorised checks (the checker's attributes of these
    names), samples grouped by patch.

    Every patch is a contiguous run of rows with its centre first; elements are contiguous
    runs of patches.
    """
    out = {"_frames": np.array([e.frame for e in els]),
           "_contact": np.array([e.contact for e in els]),
           "_hull": np.concatenate([e.hull for e in els]),
           "_hull_start": np.r_[0, np.cumsum([len(e.hull) for e in els])[:-1]],
           "_hull_element": np.repeat(np.arange(len(els)), [len(e.hull) for e in els]),
           "_sphere": np.array([e.centre for e in els]),
           "_radius": np.array([e.radius for e in els])}
    samples, offsets, starts, sizes, owner, last, rows = [], [], [], [], [], [], 0
    for i, e in enumerate(els):
        is_centre = np.zeros(len(e.samples), dtype=bool)
        is_centre[e.centres] = True
        order = np.lexsort((~is_centre, e.parent))
        parent = e.parent[order]
        first = np.flatnonzero(np.r_[True, parent[1:] != parent[:-1]])
        samples.append(e.samples[order])
        offsets.append(e.samples[order] - e.samples[e.centres[parent]])
        starts.append(rows + first)
        sizes.append(np.diff(np.r_[first, len(order)]))
        owner.append(np.full(len(first), i))
        vertex = np.flatnonzero(order == len(e.samples) - 1)[0]
        last.append(int(np.searchsorted(first, vertex, "right") - 1))
        rows += len(order)
    offsets = np.concatenate(offsets)
    reach = np.linalg.norm(offsets, axis=1)
    patch_start = np.concatenate(starts)
    margin = _PREDICTION_ERROR + _PREDICTION_SLOPE * reach
    margin[patch_start] = 0.0  # the centres
    patch_radius = np.maximum.reduceat(reach, patch_start)
    element_patches = np.r_[0, np.cumsum([len(x) for x in starts])]
    out.update({
        "_samples": np.concatenate(samples), "_offsets": offsets, "_margin": margin,
        "_patch_start": patch_start, "_patch_size": np.concatenate(sizes),
        "_patch_element": np.concatenate(owner), "_patch_radius": patch_radius,
        "_patch_margin": _PREDICTION_ERROR + _PREDICTION_SLOPE * patch_radius,
        "_box_lo": np.minimum.reduceat(offsets, patch_start),
        "_box_hi": np.maximum.reduceat(offsets, patch_start),
        "_element_patches": element_patches,
        "_last_patch": element_patches[:-1] + np.array(last),  # patch of the last vertex
    })
    return out


def _segment_any(mask: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Per segment (runs beginning at ``starts``, none empty): does ``mask`` hold anywhere?"""
    return np.logical_or.reduceat(mask, starts)


class _Check:
    """One check of the posed elements (see the module docs for what it computes).

    Element by element: planes from the hull; bounding spheres cull elements wholly outside the
    object; the patch centres of the rest get the exact tangent-plane signed distance, patches
    that may hold samples inside the object (or nearest to it) are opened, their samples get a
    first-order prediction with an error bound, and the samples that can change a verdict, the
    deepest value or the clearance are evaluated exactly.
    """

    def __init__(self, checker: CollisionChecker, poses: np.ndarray):
        self.c, self.poses = checker, poses
        c = checker
        n = len(c._elements)
        R, t = poses[:, :3, :3], poses[:, :3, 3]
        eh = c._hull_element
        hull = np.einsum("hij,hj->hi", R[eh], c._hull) + t[eh]
        lo, hi = np.minimum.reduceat(hull, c._hull_start), np.maximum.reduceat(hull, c._hull_start)
        self.depth = np.zeros(n)
        self.where: list[str | None] = [None] * n
        self.clearance = np.inf
        for plane in c.obstacles:
            h = np.minimum.reduceat(plane.height(hull), c._hull_start)
            self.clearance = min(self.clearance, max(float(h.min()), 0.0))
            for i in np.flatnonzero(-h > self.depth):
                self.depth[i], self.where[i] = -h[i], plane.name
        near = np.all(hi >= c._lo, axis=1) & np.all(lo <= c._hi, axis=1)
        if c._voxels is not None and near.any():
            near[near] = ~c._voxels.clear(lo[near] - _VOXEL_MARGIN, hi[near] + _VOXEL_MARGIN)
        # Bounding spheres: the signed distance of the centre less the radius bounds the element's
        # (an element wholly outside by a margin neither penetrates nor needs its samples tested);
        # the distance to the nearest object point plus the radius bounds its clearance.
        candidates = np.flatnonzero(near | ~c._contact)
        centres = np.einsum("eij,ej->ei", R[candidates], c._sphere[candidates]) + t[candidates]
        sd, _, nearest, _ = c._surface.evaluate(centres)
        lower = np.minimum(sd, nearest - c._cover) - c._radius[candidates]
        free = ~c._contact[candidates]
        self.clearance_bound = self.clearance
        if free.any():
            self.clearance_bound = min(self.clearance, float((nearest + c._radius[candidates])[free].min()))
        self.deep = np.zeros(n, dtype=bool)
        self.deep[candidates[near[candidates] & (lower < _CULL_MARGIN)]] = True
        self.apart = np.zeros(n, dtype=bool)
        self.apart[candidates[free & (lower < self.clearance_bound)]] = True

    def report(self) -> CollisionReport:
        c = self.c
        if (self.deep | self.apart).any():
            self._sample_tests()
        colliding = [c._elements[i].link for i in np.flatnonzero(self.depth > c.tolerance)]
        worst = int(np.argmax(self.depth))
        penetration = float(self.depth[worst])
        free = not colliding
        return CollisionReport(
            collision_free=free, penetration=penetration, clearance=float(self.clearance),
            colliding_links=tuple(dict.fromkeys(colliding)),
            obstacle=None if free else self.where[worst],
        )

    # ------------------------------------------------------------------ samples
    def _sample_tests(self) -> None:
        c = self.c
        act = np.flatnonzero(self.deep | self.apart)
        first = c._element_patches[act]
        counts = c._element_patches[act + 1] - first
        patch = np.repeat(first - np.r_[0, np.cumsum(counts)[:-1]], counts) + np.arange(counts.sum())
        pe = c._patch_element[patch]
        R, t = self.poses[:, :3, :3], self.poses[:, :3, 3]
        centre = np.einsum("pij,pj->pi", R[pe], c._samples[c._patch_start[patch]]) + t[pe]
        # A patch farther from the object's box than its radius (or whose ball lies in voxels
        # outside a mesh object) holds no sample inside the object; one farther than its radius
        # plus the clearance bound none nearer to it.
        gap = np.linalg.norm(np.maximum(np.maximum(c._lo - centre, centre - c._hi), 0.0), axis=1)
        rho = c._patch_radius[patch]
        outside = gap > rho
        if c._voxels is not None:
            test = np.flatnonzero(self.deep[pe] & ~outside)
            reach = (rho[test] + _VOXEL_MARGIN)[:, None]
            outside[test] = c._voxels.clear(centre[test] - reach, centre[test] + reach)
            gap = np.maximum(gap, c._voxels.distance_below(centre))
        need = self.deep[pe] & ~outside
        need[np.searchsorted(patch, c._last_patch[act])] = True
        taken = np.flatnonzero(need)
        sd, normal, nearest, foot = c._surface.evaluate(centre[taken])
        # patches for the clearance: those that may hold samples nearer than an evaluated centre
        bound = self.clearance_bound
        seen = self.apart[pe[taken]]
        if seen.any():
            bound = min(bound, float(nearest[seen].min()))
        more = np.flatnonzero(self.apart[pe] & ~need & (gap - rho < bound))
        if len(more):
            need[more] = True
            extra = c._surface.evaluate(centre[more])
            order = np.argsort(np.r_[taken, more])
            sd, normal, nearest, foot = (np.concatenate([a, b])[order]
                                         for a, b in zip((sd, normal, nearest, foot), extra))
        self.outside_patch = np.zeros(len(self.depth), dtype=bool)  # elements with such a patch
        self.outside_patch[pe[~need & outside]] = True
        patch, pe, centre = patch[need], pe[need], centre[need]
        counts = np.bincount(np.searchsorted(act, pe), minlength=len(act))
        element_start = np.r_[0, np.cumsum(counts)[:-1]]  # first patch of each active element
        Rp = R[pe]
        m = np.einsum("pij,pi->pj", Rp, normal)  # the gradient in the link frame: R^T n
        # lowest first-order prediction over each patch (its offsets' bounding box) and less the
        # prediction error bound
        low = sd + np.minimum(c._box_lo[patch] * m, c._box_hi[patch] * m).sum(axis=1)
        low_bound = low - c._patch_margin[patch]
        deep, contact = self.deep[pe], c._contact[pe]
        centre_depth = np.maximum.reduceat(-sd, element_start)[np.repeat(np.arange(len(act)), counts)]
        opened = deep & (low_bound < -c.tolerance)  # the verdict
        opened |= deep & (low < -(np.maximum(centre_depth, 0.0) + _DEPTH_RESOLUTION))  # the value
        touching = centre_depth > 0.0
        opened |= deep & ~contact & ~touching & (low_bound < 0.0)  # does a non-contact element touch?
        wholly_inside = ~(np.logical_or.reduceat(sd >= 0.0, element_start)
                          | self.outside_patch[act])[np.repeat(np.arange(len(act)), counts)]
        opened |= deep & wholly_inside
        clear = np.flatnonzero(self.apart[pe])
        if len(clear):  # the patches nearest the object of elements that need their clearance
            opened[clear[np.argsort(nearest[clear])[:_CLEARANCE_PATCHES]]] = True
        sizes = np.where(opened, c._patch_size[patch], 1)
        row_start = np.r_[0, np.cumsum(sizes)[:-1]]
        rp = np.repeat(np.arange(len(patch)), sizes)  # row -> position in `patch`
        rows = np.repeat(c._patch_start[patch] - row_start, sizes) + np.arange(sizes.sum())
        self.pred = sd[rp] + np.einsum("ni,ni->n", c._offsets[rows], m[rp])
        self.margin = np.where(opened[rp], c._margin[rows], 0.0)
        self.rows, self.rp, self.Rp, self.tp = rows, rp, Rp, t[pe]
        self.foot = foot
        self.owner = pe[rp]
        counts_rows = np.add.reduceat(sizes, element_start)
        self.seg = np.r_[0, np.cumsum(counts_rows)[:-1]]  # first row of each active element
        self.act = act
        last_rows = row_start[np.searchsorted(patch, c._last_patch[act])]
        self._refine()
        self._depths(last_rows)
        self._clearance()

    def _world(self, rows: np.ndarray) -> np.ndarray:
        """Object-frame positions of the given rows, (M, 3)."""
        p = self.rp[rows]
        return np.einsum("nij,nj->ni", self.Rp[p], self.c._samples[self.rows[rows]]) + self.tp[p]

    def _evaluate(self, rows: np.ndarray) -> None:
        self.pred[rows] = self.c._surface.evaluate(self._world(rows))[0]
        self.margin[rows] = 0.0

    def _deepest_known(self) -> np.ndarray:
        known = self.margin == 0.0
        return np.maximum(np.maximum.reduceat(np.where(known, -self.pred, -np.inf), self.seg), 0.0)

    def _refine(self) -> None:
        """Evaluate exactly the samples that can change a verdict, the deepest value, whether a
        non-contact element touches, or whether an element lies wholly inside.

        The first round takes each element's deepest-looking candidates for the verdict, the value
        and touching; later rounds all remaining verdict candidates of unsettled elements and the
        value's candidates while the deepest value grows.
        """
        c, seg, owner = self.c, self.seg, self.owner
        deep = self.deep[owner]
        free = deep & ~c._contact[owner]
        position = self._position(owner)
        deepest = self._deepest_known()
        improving = np.ones(len(self.act), dtype=bool)
        for round_ in range(3):
            known = self.margin == 0.0
            unknown = deep & ~known
            if not unknown.any():
                break
            lo, hi = self.pred - self.margin, self.pred + self.margin
            verdict = unknown & (deepest[position] <= c.tolerance) & (-lo > c.tolerance)
            overall = max(float(deepest.max()), float(self.depth.max()))  # the report's is the deepest
            value = unknown & (-self.pred > overall + _DEPTH_RESOLUTION) & improving[position]
            want = self._deepest_looking(value)
            if round_ == 0:
                want |= self._deepest_looking(verdict)
                if self.clearance > 0.0:  # does a non-contact element touch?
                    touching = _segment_any(known & (self.pred < 0.0), seg)[position]
                    want |= self._deepest_looking(unknown & free & ~touching & (lo < 0.0))
            else:
                want |= verdict
            outside = (_segment_any(lo >= 0.0, seg) | self.outside_patch[self.act])[position]
            want |= unknown & ~outside & (hi >= 0.0)  # wholly inside?
            rows = np.flatnonzero(want)
            if not len(rows):
                break
            self._evaluate(rows)
            now = self._deepest_known()
            improving, deepest = now > deepest, now

    def _deepest_looking(self, mask: np.ndarray) -> np.ndarray:
        """The ``_DEEPEST_CANDIDATES`` rows of ``mask`` with the lowest prediction, per element."""
        out = np.zeros(len(mask), dtype=bool)
        rows = np.flatnonzero(mask)
        if len(rows):
            rows = rows[np.lexsort((self.pred[rows], self.owner[rows]))]
            group = self.owner[rows]
            begin = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
            rank = np.arange(len(rows)) - np.repeat(begin, np.diff(np.r_[begin, len(rows)]))
            out[rows[rank < _DEEPEST_CANDIDATES]] = True
        return out

    def _position(self, owner: np.ndarray) -> np.ndarray:
        """Position in ``self.act`` of elements ``owner``."""
        return np.searchsorted(self.act, owner)

    def _depths(self, last_rows: np.ndarray) -> None:
        c, seg = self.c, self.seg
        deep = self.deep[self.act]
        if not deep.any():
            return
        known = self.margin == 0.0
        inside_any = _segment_any((known & (self.pred < 0.0)) | (self.pred + self.margin < 0.0), seg)
        outside_any = _segment_any(self.pred - self.margin >= 0.0, seg) | self.outside_patch[self.act]
        deepest = self._deepest_known()
        inner = c._object_inside(self.act[deep], self.poses)
        for k in np.flatnonzero(deep):
            i = self.act[k]
            d_out = inner.get(i, 0.0)
            if inside_any[k] and not outside_any[k] and d_out == 0.0:  # wholly inside: a vertex tells
                d = max(0.0, -float(self.pred[last_rows[k]]))
            else:
                d = max(float(deepest[k]), d_out)
            if d > self.depth[i]:
                self.depth[i], self.where[i] = d, "object"
            if d > 0.0 and not c._contact[i]:
                self.clearance = 0.0

    def _clearance(self) -> None:
        if self.clearance == 0.0:
            return
        rows = np.flatnonzero(self.apart[self.owner])
        if not len(rows):
            return
        # the samples nearest the nearest samples of the object seen from the centres
        world = self._world(rows)
        far = np.linalg.norm(world - self.foot[self.rp[rows]], axis=1)
        take = np.argsort(far)[:_CLEARANCE_CANDIDATES]
        self.clearance = min(self.clearance, self.c._clearance_of(world[take], self.owner[rows[take]],
                                                                  self.poses))
