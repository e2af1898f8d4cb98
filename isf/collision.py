"""Collision checks of a fitted grasp: the whole gripper against the object and obstacle planes.

Every :class:`~isf.gripper.LinkGeometry` of the gripper (an *element*) is posed at
``T_object_gripper @ T_gripper_link(q)`` and compared with the object surface and with each
obstacle :class:`Plane`, all in the object frame, metres.

Penetration depth (how deep gripper geometry sits inside the object or an obstacle)
    * **Planes:** exact. A linear height attains its minimum over a mesh at a vertex, so the
      lowest convex-hull vertex of each element gives its depth below the plane.
    Both depth estimates run only for elements whose surface crosses the object's, which
    coal tells exactly (an element that crosses nothing is wholly outside, or wholly inside,
    where any one of its vertices gives the depth estimate).

    * **Gripper into object:** points sampled evenly (1 mm, at most 800) on each element's surface, plus
      its vertices, get the signed distance ``(p - o) . n_o`` from their nearest object point
      ``o`` with outward normal ``n_o``, taken as the largest of ``(p - o_k) . n_k`` over its
      6 nearest object points: a point is inside only when it lies below every nearby tangent
      plane, which keeps points beside a convex edge of the object outside (the price: a
      shallow penetration right at a concave crease of the object can read as none). This
      works for meshes and point clouds alike; a closed mesh object is resampled at 1 mm.
    * **Object into gripper:** coal (``coal.collide``, BVH against the object's BVH or, for a
      point cloud, its OcTree) tells exactly whether an element's surface crosses the object's.
      Only then are the object's points tested for lying inside the (closed) element: exactly
      by its face planes when it is convex, else with the same tangent-plane estimate on the
      element's own surface samples. This finds
      thin object features poking into the gripper between its samples.

    An element whose depth exceeds ``tolerance`` collides. The default 2 mm accepts the
    residual of a converged fit (pads sit on the object within a fraction of a millimetre),
    the discretisation of the object samples and the compliance of real finger pads, while a
    gripper part that truly intersects the object goes deeper than that.

Clearance
    the smallest distance from a *non-contact* element's surface samples to the nearest object
    point (contact elements are meant to touch), and from *every* element's hull to each
    obstacle plane; 0 when a non-contact element touches or penetrates the object, or any
    element an obstacle.
    *Contact elements* are those the contact-surface points of their link lie on (or, when none
    does, every element of that link).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial import cKDTree

from .exceptions import GripperDescriptionError, InvalidInputError
from .gripper import Gripper, LinkGeometry
from .object_surface import ObjectSurface

__all__ = ["CollisionChecker", "CollisionReport", "Plane"]

logger = logging.getLogger(__name__)

_SAMPLE_SPACING = 0.001  # gripper surface samples, m
_MAX_SAMPLES = 800  # per element (spacing grows on large elements)
_OBJECT_SPACING = 0.001  # resampling of a closed mesh object, m
_MAX_OBJECT_SAMPLES = 50000
_NEIGHBOURS = 6  # tangent planes of the nearest object points a point must lie below to be inside
_ON_SURFACE = 1e-6  # a contact point this close to an element lies on it, m


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


def _even_samples(mesh: trimesh.Trimesh, spacing: float, max_points: int,
                  rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Area-uniform surface samples (about one per ``spacing^2``) and their face normals."""
    n = int(np.clip(mesh.area / spacing**2, 1, max_points))
    areas = mesh.area_faces
    face = rng.choice(len(areas), size=n, p=areas / areas.sum())
    u, v = rng.random((2, n))
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    tri = mesh.triangles[face]
    points = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return points, mesh.face_normals[face]


def _point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Exact distance of each point (M, 3) to the nearest of the triangles (F, 3, 3), metres (M,)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    p = points[:, None, :]
    n = np.cross(b - a, c - a)
    n2 = np.maximum(np.einsum("fi,fi->f", n, n), 1e-300)
    foot = p - (np.einsum("mfi,fi->mf", p - a, n) / n2)[..., None] * n
    inside = np.ones(foot.shape[:2], dtype=bool)
    for x, y in ((a, b), (b, c), (c, a)):  # the foot lies inside when every edge sees it on n's side
        inside &= np.einsum("mfi,fi->mf", np.cross(y - x, foot - x), n) >= 0
    best = np.where(inside, np.linalg.norm(p - foot, axis=2), np.inf)
    for x, y in ((a, b), (b, c), (c, a)):  # else the nearest point lies on an edge
        d = y - x
        s = np.clip(np.einsum("mfi,fi->mf", p - x, d) / np.maximum(np.einsum("fi,fi->f", d, d), 1e-300), 0, 1)
        best = np.minimum(best, np.linalg.norm(p - (x + s[..., None] * d), axis=2))
    return best.min(axis=1)


def _bvh(vertices: np.ndarray, faces: np.ndarray) -> coal.BVHModelOBBRSS:
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(faces), len(vertices))
    model.addVertices(np.ascontiguousarray(vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(faces, dtype=np.int64))
    model.endModel()
    return model


class _TangentPlanes:
    """Surface points with outward normals: a signed-distance estimate from nearby tangent planes.

    A query point's signed distance is the largest of ``(p - o_k) . n_k`` over its
    ``_NEIGHBOURS`` nearest surface points ``o_k``: a point is inside only when it lies below
    every nearby tangent plane (see the module docs).
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, spacing: float):
        self.points = np.ascontiguousarray(points, dtype=float)
        self.normals = np.ascontiguousarray(normals, dtype=float)
        self.spacing = float(spacing)
        """Typical distance between neighbouring points, metres."""
        self.tree = cKDTree(self.points)

    def signed_distance(self, query: np.ndarray) -> np.ndarray:
        """Estimated signed distance of points (M, 3), metres (M,), negative inside."""
        if len(query) == 0:
            return np.empty(0)
        k = min(_NEIGHBOURS, len(self.points))
        _, idx = self.tree.query(query, k=k, workers=1)
        idx = idx.reshape(len(query), k)
        heights = np.einsum("mki,mki->mk", query[:, None, :] - self.points[idx], self.normals[idx])
        return heights.max(axis=1)

    def depth(self, query: np.ndarray) -> float:
        """Deepest of the points (M, 3) below the surface, metres (0 if none)."""
        sd = self.signed_distance(query)
        return float(max(0.0, -sd.min())) if len(sd) else 0.0


class _Element:
    """One gripper geometry element, precomputed in its link frame."""

    def __init__(self, geom: LinkGeometry, frame: int, rng: np.random.Generator):
        self.link, self.name, self.frame = geom.link, geom.name, frame
        mesh = trimesh.Trimesh(np.asarray(geom.vertices, float), np.asarray(geom.faces, np.int64),
                               process=True, validate=False)
        self.mesh = mesh
        try:
            with np.errstate(invalid="ignore", divide="ignore"):  # flat sheets: zero hull volume
                self.hull = np.asarray(mesh.convex_hull.vertices, dtype=float)
        except Exception:  # qhull fails on flat or degenerate geometry
            self.hull = np.asarray(mesh.vertices, dtype=float)
        samples, normals = _even_samples(mesh, _SAMPLE_SPACING, _MAX_SAMPLES, rng)
        self.samples = np.concatenate([samples, mesh.vertices])
        self.closed = bool(mesh.is_watertight and mesh.is_winding_consistent)
        self.planes = None
        if self.closed:  # to find object points inside the element
            sign = np.sign(mesh.volume)
            if mesh.is_convex:  # exact: the largest signed distance to its face planes
                n = sign * mesh.face_normals
                self.planes = np.c_[n, np.einsum("ij,ij->i", n, mesh.triangles[:, 0])]
            else:
                self.surface = _TangentPlanes(samples, normals * sign, np.sqrt(mesh.area / len(samples)))
        self.bvh = _bvh(mesh.vertices, mesh.faces)
        self.contact = False


class CollisionChecker:
    """Checks posed grippers against one object and fixed obstacle planes.

    Build it once per (gripper, object) pair; :meth:`check` is then cheap.

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
        rng = np.random.default_rng(0)
        links = list(dict.fromkeys(g.link for g in gripper.geometries))
        missing = [link for link in links if not gripper.model.existFrame(link)]
        if missing:
            raise GripperDescriptionError(gripper.name, [
                f"a geometry belongs to link {link!r}, which the model lacks; fix its link name"
                for link in missing])
        self._links = links
        self._frame_ids = [gripper.model.getFrameId(link) for link in links]
        self._data = gripper.model.createData()
        self._elements = [_Element(g, links.index(g.link), rng) for g in gripper.geometries]
        self._mark_contact_elements(gripper)
        self._surface = _TangentPlanes(*self._object_samples(obj, rng))
        self._points = obj.points  # probes for object points inside gripper elements
        self._lo, self._hi = self._surface.points.min(axis=0), self._surface.points.max(axis=0)
        self._object_geometry = self._coal_object(obj)
        self._request = coal.CollisionRequest()
        self._request.enable_contact = False
        self._result = coal.CollisionResult()
        self._identity = coal.Transform3s()
        # Clearance needs no more than 0.1 mm + 2 %: letting coal stop there prunes its traversal.
        self._distance_request = coal.DistanceRequest()
        self._distance_request.abs_err = 1e-4
        self._distance_request.rel_err = 0.02

    # ------------------------------------------------------------------ set-up
    def _mark_contact_elements(self, gripper: Gripper) -> None:
        for link in dict.fromkeys(s.link for s in gripper.surfaces):
            points = np.concatenate([s.points for s in gripper.surfaces if s.link == link]).astype(float)
            mine = [e for e in self._elements if e.link == link]
            probe = points[:: max(1, len(points) // 32)]
            hits = [e for e in mine if _point_triangle_distance(probe, e.mesh.triangles).max() <= _ON_SURFACE]
            for e in hits or mine:
                e.contact = True

    @staticmethod
    def _object_samples(obj: ObjectSurface, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float]:
        """Dense samples of a closed, outward mesh object (points, normals, spacing); else the object's own."""
        if not obj.is_mesh:
            return obj.points, obj.normals, obj.spacing
        mesh = trimesh.Trimesh(np.asarray(obj.mesh_vertices, float), np.asarray(obj.mesh_faces, np.int64),
                               process=False, validate=False)
        if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
            logger.debug("%s: mesh not closed and outward; collision checks use its points", obj.name)
            return obj.points, obj.normals, obj.spacing
        spacing = min(obj.spacing, _OBJECT_SPACING)
        points, normals = _even_samples(mesh, spacing, _MAX_OBJECT_SAMPLES, rng)
        spacing = float(np.sqrt(mesh.area / len(points)))
        return np.concatenate([obj.points, points]), np.concatenate([obj.normals, normals]), spacing

    @staticmethod
    def _coal_object(obj: ObjectSurface):
        if obj.is_mesh:
            return _bvh(np.asarray(obj.mesh_vertices, float), np.asarray(obj.mesh_faces, np.int64))
        return coal.makeOctree(np.ascontiguousarray(obj.points, dtype=np.float64), max(obj.spacing, 1e-4))

    # ------------------------------------------------------------------- check
    def _link_poses(self, T: np.ndarray, q: np.ndarray) -> list[np.ndarray]:
        pin.framesForwardKinematics(self.gripper.model, self._data, q)
        return [T @ self._data.oMf[fid].homogeneous for fid in self._frame_ids]

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

    def _surfaces_cross(self, e: _Element, T_e: np.ndarray) -> bool:
        """True when the surface of element ``e`` posed at ``T_e`` crosses the object's (coal)."""
        self._result.clear()
        return bool(coal.collide(e.bvh, coal.Transform3s(T_e[:3, :3], T_e[:3, 3]), self._object_geometry,
                                 self._identity, self._request, self._result))

    def _depth_object_into(self, e: _Element, T_e: np.ndarray) -> float:
        """Deepest object point inside element ``e`` posed at ``T_e``, metres (0 if none)."""
        world = T_e[:3, :3] @ e.hull.T
        lo, hi = world.min(axis=1) + T_e[:3, 3], world.max(axis=1) + T_e[:3, 3]
        near = np.all((self._points >= lo) & (self._points <= hi), axis=1)
        if not e.closed or not near.any():
            return 0.0
        local = (self._points[near] - T_e[:3, 3]) @ T_e[:3, :3]
        if e.planes is not None:
            sd = (local @ e.planes[:, :3].T - e.planes[:, 3]).max(axis=1)
            return float(max(0.0, -sd.min()))
        return e.surface.depth(local)

    def _distance(self, e: _Element, T_e: np.ndarray, samples: np.ndarray, bound: float) -> float:
        """Distance from element ``e`` (posed at ``T_e``, surface ``samples``) to the object, metres.

        Coal's BVH-to-BVH distance for a mesh object (to 0.1 mm + 2 %); for a point cloud, the distance from the
        element's samples to the nearest object point (a coarse pass bounds the fine one).
        """
        if self.object.is_mesh:
            result = coal.DistanceResult()
            return float(coal.distance(e.bvh, coal.Transform3s(T_e[:3, :3], T_e[:3, 3]), self._object_geometry,
                                       self._identity, self._distance_request, result))
        tree = self._surface.tree
        bound = min(bound, float(tree.query(samples[::8], workers=1)[0].min()))
        dist, _ = tree.query(samples, workers=1, distance_upper_bound=bound + 1e-12)
        return float(dist.min())

    def check(self, T_object_gripper: np.ndarray, q: np.ndarray) -> CollisionReport:
        """Check the gripper at palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,).

        Raises:
            InvalidInputError: ``T_object_gripper`` is not a rigid transform or ``q`` has the wrong size.
        """
        T, q = self._check_inputs(T_object_gripper, q)
        poses = self._link_poses(T, q)
        worst, worst_where, colliding = 0.0, None, []
        clearance = np.inf
        for e in self._elements:
            T_e = poses[e.frame]
            R, t = T_e[:3, :3], T_e[:3, 3]
            hull = e.hull @ R.T + t
            depth, where = 0.0, None
            for plane in self.obstacles:
                h = float(plane.height(hull).min())
                clearance = min(clearance, max(h, 0.0))
                if -h > depth:
                    depth, where = -h, plane.name
            margin = 0.0 if e.contact else clearance
            near = np.all(hull.max(axis=0) >= self._lo - margin) and np.all(hull.min(axis=0) <= self._hi + margin)
            if near or not e.contact:
                samples = e.samples @ R.T + t
                in_box = np.all((samples >= self._lo) & (samples <= self._hi), axis=1)
                d_in = d_out = 0.0
                if near and self._surfaces_cross(e, T_e):
                    d_in = self._surface.depth(samples[in_box])
                    d_out = self._depth_object_into(e, T_e)
                elif near:  # no crossing: wholly outside, or wholly inside (then any vertex tells)
                    d_in = self._surface.depth(samples[-1:])
                d = max(d_in, d_out)
                if d > depth:
                    depth, where = d, "object"
                if not e.contact:
                    if d > 0.0:
                        clearance = 0.0
                    else:
                        clearance = min(clearance, self._distance(e, T_e, samples, clearance))
            if depth > self.tolerance:
                colliding.append(e.link)
            if depth > worst:
                worst, worst_where = depth, where
        free = not colliding
        return CollisionReport(
            collision_free=free, penetration=worst, clearance=float(clearance),
            colliding_links=tuple(dict.fromkeys(colliding)), obstacle=None if free else worst_where,
        )
