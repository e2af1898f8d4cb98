"""Collision checks of a fitted grasp: the whole gripper against the object and obstacle planes.

Every :class:`~isf.gripper.LinkGeometry` of the gripper is posed at
``T_object_gripper @ T_gripper_link(q)`` and compared with the object surface and with each
obstacle :class:`Plane` (all in the object frame, metres).

Penetration (how deep gripper geometry sits inside the object or an obstacle)
    * Planes: exact. A linear height attains its minimum over a mesh at a vertex, so the
      lowest convex-hull vertex of each geometry gives its depth below the plane.
    * Object, gripper into object: points sampled evenly on each geometry's surface (plus its
      vertices) get the signed distance ``sd(p) = (p - o) . n_o`` from their nearest object
      sample ``o`` with outward normal ``n_o`` (negative inside). It is exact over flat object
      faces, works for meshes and point clouds alike, and near sharp object edges errs by at
      most about the object sample spacing. A mesh object is therefore resampled densely
      (spacing ``min(obj.spacing, max(tolerance / 2, 0.5 mm))``, at most 60 000 points) when
      the mesh is closed and consistently wound; a point cloud is used as given.
    * Object, object into gripper: object samples inside a closed geometry element catch thin
      object features that slip between the gripper samples. Their depth below the element's
      surface is exact for convex elements (face planes) and the same sample estimate for
      others; open elements have no inside and skip this test.

    ``penetration`` is the deepest of all these; a geometry whose depth exceeds ``tolerance``
    collides. The default 2 mm accepts the residual of a converged fit (pads sit on the object
    within a fraction of a millimetre), the discretisation of the object samples (a few tenths
    of a millimetre on curved faces, up to the spacing at sharp edges of a point cloud) and
    the compliance of real finger pads, while a gripper part that truly intersects the object
    goes deeper than that within a fraction of its size.

Clearance (how far the gripper parts that should not touch anything are from touching)
    ``min`` of (a) the distance from every *non-contact* geometry element to the object and
    (b) the height of *every* geometry element above each obstacle plane, clipped at 0 (0 also
    when any of them penetrates). A geometry element is a *contact* element when the points of
    a contact surface of its link lie on it (or, when none does, every element of that link);
    contact elements are meant to touch the object, so only (b) applies to them. The object
    distance is the sample estimate above: ``(p - o) . n_o`` near a face, never less than
    ``|p - o| - spacing``. Within 2 cm it is resolved to the sample accuracy (exact for flat
    faces, about 0.1 mm on curved ones); beyond 2 cm an element's distance comes from sparse
    subsets of both surfaces and may read up to about 1 mm high. ``inf`` when there is nothing
    to measure (no non-contact geometry and no planes).

Speed: link AABBs (from convex-hull vertices) against the object's AABB decide which elements
need the sample tests; clearance is bounded coarse-to-fine, so elements far from the current
best are never sampled finely.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial import cKDTree

from .exceptions import GripperDescriptionError, InvalidInputError
from .gripper import Gripper, LinkGeometry
from .object_surface import ObjectSurface

__all__ = ["CollisionChecker", "CollisionReport", "Plane"]

logger = logging.getLogger(__name__)

_GRIPPER_SPACING = 5e-3  # sample spacing on gripper faces, m
_GRIPPER_MAX_SAMPLES = 800  # per geometry element (larger ones are sampled coarser)
_EDGE_SPACING = 2e-3  # sample spacing along sharp gripper edges, m
_EDGE_MAX_SAMPLES = 600  # per geometry element
_SHARP = 0.5  # dihedral angle that makes an edge sharp, rad
_MAX_VERTICES = 500  # elements with more vertices keep only their convex-hull vertices
_COARSE_PER_ELEMENT = 24  # coarse gripper points per element, for clearance bounds
_OBJECT_MIN_SPACING = 0.5e-3  # finest resampling of a mesh object, m
_OBJECT_MAX_SAMPLES = 60_000
_OBJECT_COARSE_SPACING = 5e-3  # coarse object subset, for clearance bounds, m
_NEAR = 0.02  # clearance within this is read on the full object samples, m
_FAR = 0.02  # clearance beyond this comes from the coarse subsets only, m
_OBJECT_MAX_FEATURES = 5000  # mesh vertices (if no more) and sharp-edge points of the object
_DEEP = 0.01  # gripper points farther than this from the object surface are read on the coarse subset, m
_ON_SURFACE = 1e-6  # a contact point this close to an element lies on it, m
_EYE = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


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
        collision_free: no geometry penetrates the object or an obstacle deeper than the tolerance.
        penetration: deepest penetration of any gripper geometry into the object or an obstacle,
            metres (0 if none).
        clearance: distance from the non-contact geometry to the object and from all geometry to
            the obstacle planes, metres; 0 when touching or penetrating (see the module docs).
        colliding_links: links whose geometry penetrates deeper than the tolerance, in the order
            of ``gripper.geometries``.
        obstacle: ``"object"`` or the plane's name for the deepest violation; None when
            collision-free.
    """

    collision_free: bool
    penetration: float
    clearance: float
    colliding_links: tuple[str, ...] = ()
    obstacle: str | None = None


# ------------------------------------------------------------------ sampling helpers
def _face_frame(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Twice the area (F,) and unit normals (F, 3) of each triangle (zero normal if degenerate)."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    cross = np.cross(v1 - v0, v2 - v0)
    dbl = np.linalg.norm(cross, axis=1)
    return dbl, cross / np.where(dbl > 0, dbl, 1.0)[:, None]


def _voxel_thin(points: np.ndarray, size: float) -> np.ndarray:
    """Indices keeping the first point of every occupied voxel of edge ``size``."""
    keys = np.floor((points - points.min(axis=0)) / size).astype(np.int64)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, first = np.unique(flat, return_index=True)
    return np.sort(first)


def _surface_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float, max_points: int,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float]:
    """Evenly spaced points on a triangle mesh with their face normals.

    Random area-weighted samples are thinned to one per voxel of edge ``spacing`` (grown so at
    most about ``max_points`` remain).

    Returns:
        (points (N, 3), unit normals (N, 3), the spacing used in metres).
    """
    dbl, normals = _face_frame(vertices, faces)
    area = 0.5 * dbl.sum()
    if not area > 0:
        return np.empty((0, 3)), np.empty((0, 3)), spacing
    spacing = max(spacing, float(np.sqrt(1.5 * area / max_points)))
    n_draw = int(np.clip(6.0 * area / spacing**2, 64, 6 * max_points))
    tri = rng.choice(len(faces), size=n_draw, p=dbl / dbl.sum())
    r1, r2 = np.sqrt(rng.random(n_draw)), rng.random(n_draw)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    points = np.einsum("nk,nkd->nd", bary, vertices[faces[tri]])
    keep = _voxel_thin(points, spacing)
    return points[keep], normals[tri[keep]], spacing


def _farthest_points(points: np.ndarray, k: int) -> np.ndarray:
    """Indices of ``k`` farthest-point samples of ``points`` (starting at index 0)."""
    k = min(k, len(points))
    chosen = np.empty(k, dtype=np.int64)
    chosen[0] = 0
    dist = np.linalg.norm(points - points[0], axis=1)
    for i in range(1, k):
        chosen[i] = int(np.argmax(dist))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[i]], axis=1))
    return chosen


def _edge_samples(mesh: trimesh.Trimesh, spacing: float, max_points: int) -> np.ndarray:
    """Points along the sharp (and open) edges of a mesh, ``spacing`` apart, endpoints excluded, (N, 3)."""
    sharp = mesh.face_adjacency_edges[mesh.face_adjacency_angles > _SHARP]
    open_edges = mesh.edges_sorted[trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)]
    edges = np.concatenate([sharp, open_edges]).reshape(-1, 2)
    if not len(edges):
        return np.empty((0, 3))
    a, b = mesh.vertices[edges[:, 0]], mesh.vertices[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    spacing = max(spacing, float(length.sum()) / max_points)
    count = np.floor(length / spacing).astype(np.int64)  # interior points per edge
    edge = np.repeat(np.arange(len(edges)), count)
    rank = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + 1
    s = (rank / (count[edge] + 1))[:, None]
    return a[edge] + s * (b[edge] - a[edge])


class _SurfaceModel:
    """Points with outward normals and a KD-tree: the signed-distance estimate of a surface.

    Each sample stands for a disk of radius ``1.5 spacing`` in its tangent plane (wide enough
    to close the gaps of random sampling). A query point ``p`` is read against those of its 8
    nearest samples whose disk it projects into: its height ``h = (p - o) . n_o`` above the
    one with the smallest ``|h|`` (exact over flat faces, negative inside). Near a sharp edge
    the faces disagree, and the shape of the edge decides. At a convex edge (the two samples
    lie below each other's tangent planes) the object lies below both planes, so the reading
    is the largest ``h`` of the two; this holds for any of the 8 samples, whether or not
    ``p`` projects into its disk. At a concave edge the object is locally the union of the
    half-spaces, and the reading is the smallest ``h`` of the two. (On smooth surfaces the
    same rule picks the tightest tangent-plane bound: a convex body lies below every tangent
    plane.) A point that projects into no disk lies beyond a convex edge or corner, outside,
    and reads its distance to the nearest sample (an upper bound).

    Attributes:
        points, normals: (N, 3) samples and unit outward normals.
        spacing: sample spacing, metres.
        tree: KD-tree of ``points``.
    """

    neighbours = 8
    disk = 1.5  # disk radius / spacing
    edge = 0.1  # |offset| / spacing that makes two samples' faces an edge

    def __init__(self, points: np.ndarray, normals: np.ndarray, spacing: float):
        self.points = np.ascontiguousarray(points, dtype=float)
        self.normals = np.ascontiguousarray(normals, dtype=float)
        self.spacing = float(spacing)
        self.tree = cKDTree(self.points)

    def signed_distance(self, query: np.ndarray, bound: float = np.inf) -> np.ndarray:
        """Estimated signed distance of query points (M, 3) to the surface, metres (M,).

        Points with no sample within ``bound`` get ``inf``.
        """
        m, n = len(query), len(self.points)
        if m == 0:
            return np.empty(0)
        k = min(self.neighbours, n)
        dist, idx = self.tree.query(query, k=k, distance_upper_bound=bound, workers=1)
        dist, idx = dist.reshape(m, k), idx.reshape(m, k)
        found = np.isfinite(dist)
        idx = np.minimum(idx, n - 1)  # missing neighbours (dist inf) never take part
        q, nq = self.points[idx], self.normals[idx]  # (M, k, 3)
        h = np.einsum("mki,mki->mk", query[:, None, :] - q, nq)
        r, eps, rows = self.disk * self.spacing, self.edge * self.spacing, np.arange(m)
        cand = dist * dist - h * h <= r * r  # projects into the sample's disk
        first = np.where(cand, np.abs(h), np.inf).argmin(axis=1)
        below = self._below(q, nq, first)
        reading = np.maximum(h[rows, first], np.where(found & (below < -eps), h, -np.inf).max(axis=1))
        reading = np.minimum(reading, np.where(cand & (below > eps), h, np.inf).min(axis=1))
        # Outside a convex edge: the distance to the wedge of the two planes that face p most.
        top = np.where(found, h, -np.inf).argmax(axis=1)
        pair = found & (h > 0) & (self._below(q, nq, top) < -eps)
        other = np.where(pair, h, -np.inf).argmax(axis=1)
        ha, hb = h[rows, top], h[rows, other]
        c = np.einsum("mi,mi->m", nq[rows, top], nq[rows, other])
        with np.errstate(divide="ignore", invalid="ignore"):  # parallel planes: c = 1
            a, b = (ha - c * hb) / (1 - c * c), (hb - c * ha) / (1 - c * c)
            wedge = np.where((a >= 0) & (b >= 0), np.sqrt(a * a + b * b + 2 * a * b * c),
                             np.maximum(ha, hb))
        wedge = np.where(pair[rows, other] & (ha > 0), wedge, -np.inf)
        near = dist[:, 0]  # distance to the nearest sample: an upper bound outside
        over = np.where(reading > 0, np.minimum(np.maximum(reading, wedge), near), reading)
        beyond = np.minimum(near, np.maximum(np.maximum(wedge, ha), near - self.spacing))
        return np.where(cand[rows, first], over, beyond)

    @staticmethod
    def _below(q: np.ndarray, nq: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """``(q - q_ref) . n_ref + (q_ref - q) . n`` per neighbour (M, k): negative when each of
        the pair lies below the other's tangent plane (a convex edge), positive when above."""
        rows = np.arange(len(q))
        q0, n0 = q[rows, ref][:, None, :], nq[rows, ref][:, None, :]
        return np.einsum("mki,mki->mk", q - q0, n0 - nq)


# ------------------------------------------------------------------ gripper elements
@dataclass(eq=False)
class _Element:
    """One gripper geometry element, precomputed in its link frame.

    Attributes:
        link, name: its link and name.
        frame: index of its link in the checker's link list.
        contact: True for a contact element (see the module docs).
        hull: (H, 3) convex-hull vertices (all vertices if the hull fails).
        points: (N, 3) even surface samples followed by the vertices.
        coarse: (K,) indices into ``points``: a farthest-point subset.
        parent: (N,) index into ``coarse`` of each point's nearest coarse point.
        radius: largest distance of a point to its coarse point, metres.
        planes: (F, 4) outward face planes ``[n, d]`` (inside: ``n . x < d``) when convex.
        solid: the inside estimate of a closed, non-convex element.
    """

    link: str
    name: str
    frame: int
    contact: bool
    hull: np.ndarray
    points: np.ndarray
    coarse: np.ndarray
    parent: np.ndarray
    radius: float
    planes: np.ndarray | None = None
    solid: _SurfaceModel | None = None

    @property
    def closed(self) -> bool:
        """True when object points inside it can be detected."""
        return self.planes is not None or self.solid is not None

    def face_distance(self, local: np.ndarray) -> np.ndarray:
        """Signed distance of link-frame points (M, 3) to this convex element, metres (M,).

        Exact inside (negative) and where the nearest feature is a face; ``inf`` elsewhere
        (nearest to an edge or a vertex, which the element's own samples cover).
        """
        values = local @ self.planes[:, :3].T - self.planes[:, 3]
        face = values.argmax(axis=1)
        out = values[np.arange(len(local)), face]
        foot = local - out[:, None] * self.planes[face, :3]
        on_face = (foot @ self.planes[:, :3].T - self.planes[:, 3]).max(axis=1) <= 1e-9
        return np.where(on_face | (out <= 0), out, np.inf)

    def depth_of(self, local: np.ndarray) -> float:
        """Deepest penetration of link-frame points (M, 3) into this element, metres (0 if none)."""
        if self.planes is not None:
            sd = (local @ self.planes[:, :3].T - self.planes[:, 3]).max(axis=1)
        elif self.solid is not None:
            sd = self.solid.signed_distance(local)
        else:
            return 0.0
        return max(0.0, -float(sd.min()))


def _build_element(geom: LinkGeometry, frame: int, rng: np.random.Generator) -> tuple[_Element, trimesh.Trimesh]:
    """Precompute one geometry element (and return its cleaned mesh)."""
    mesh = trimesh.Trimesh(np.asarray(geom.vertices, dtype=float), np.asarray(geom.faces, dtype=np.int64),
                           process=True, validate=False)
    try:
        hull = np.asarray(mesh.convex_hull.vertices, dtype=float)
    except Exception:  # qhull fails on flat or degenerate geometry
        hull = np.asarray(mesh.vertices, dtype=float)
    samples, normals, spacing = _surface_samples(mesh.vertices, mesh.faces, _GRIPPER_SPACING,
                                                 _GRIPPER_MAX_SAMPLES, rng)
    corners = mesh.vertices if len(mesh.vertices) <= _MAX_VERTICES else hull
    points = np.concatenate([samples, _edge_samples(mesh, _EDGE_SPACING, _EDGE_MAX_SAMPLES), corners])
    coarse = _farthest_points(points, _COARSE_PER_ELEMENT)
    radius, parent = cKDTree(points[coarse]).query(points)
    element = _Element(link=geom.link, name=geom.name, frame=frame, contact=False, hull=hull,
                       points=points, coarse=coarse, parent=parent, radius=float(radius.max()))
    if mesh.is_watertight and mesh.is_winding_consistent and len(samples):
        sign = 1.0 if mesh.volume > 0 else -1.0
        if mesh.is_convex:
            n = sign * mesh.face_normals
            element.planes = np.c_[n, np.einsum("ij,ij->i", n, mesh.triangles[:, 0])]
        else:
            element.solid = _SurfaceModel(samples, sign * normals, spacing)
    else:
        logger.debug("geometry %s of link %s is open: object points inside it are not tested",
                     geom.name, geom.link)
    return element, mesh


def _lies_on(mesh: trimesh.Trimesh, points: np.ndarray) -> bool:
    """True when most of ``points`` (link frame) lie on the mesh surface."""
    probe = points[_farthest_points(points, 32)]
    _, dist, _ = trimesh.proximity.closest_point(mesh, probe)
    return bool(np.mean(dist < _ON_SURFACE) >= 0.5)


# ------------------------------------------------------------------ the object
def _object_model(obj: ObjectSurface, tolerance: float,
                  rng: np.random.Generator) -> tuple[_SurfaceModel, np.ndarray]:
    """The object's signed-distance model and its feature points (M, 3).

    The model uses dense samples of a closed, outward-wound mesh, else the object's own
    points. Feature points are a mesh's vertices and points along its sharp edges (none for a
    point cloud).
    """
    given = _SurfaceModel(obj.points, obj.normals, obj.spacing)
    if obj.mesh_vertices is None or obj.mesh_faces is None:
        return given, np.empty((0, 3))
    vertices = np.asarray(obj.mesh_vertices, dtype=float)
    faces = np.asarray(obj.mesh_faces, dtype=np.int64)
    mesh = trimesh.Trimesh(vertices, faces, process=False, validate=False)
    model = given
    if mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0:
        spacing = min(obj.spacing, max(tolerance / 2.0, _OBJECT_MIN_SPACING))
        points, normals, spacing = _surface_samples(vertices, faces, spacing, _OBJECT_MAX_SAMPLES, rng)
        dense = _SurfaceModel(points, normals, spacing)
        _, idx = dense.tree.query(obj.points, workers=1)
        agree = float(np.mean(np.einsum("ij,ij->i", dense.normals[idx], obj.normals) > 0))
        if agree >= 0.9:
            model = dense
            logger.debug("%s: resampled %d points at %.2g m for collision checks", obj.name,
                         len(points), spacing)
        else:
            logger.warning("%s: only %.0f%% of the object's normals agree with its mesh winding; "
                           "collision checks use the object's points", obj.name, 100 * agree)
    else:
        logger.debug("%s: mesh is not closed and outward; using its %d points", obj.name, obj.n_points)
    features = np.concatenate([_edge_samples(mesh, max(model.spacing, _EDGE_SPACING), _OBJECT_MAX_FEATURES),
                               vertices if len(vertices) <= _OBJECT_MAX_FEATURES else np.empty((0, 3))])
    return model, features


class _BoxIndex:
    """Points sorted along x, for the points inside an axis-aligned box."""

    def __init__(self, points: np.ndarray):
        self.points = points[np.argsort(points[:, 0])]
        self.x = np.ascontiguousarray(self.points[:, 0])

    def inside(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The points in the box [lo, hi], (M, 3)."""
        a, b = np.searchsorted(self.x, (lo[0], hi[0]))
        pts = self.points[a:b]
        return pts[np.all((pts >= lo) & (pts <= hi), axis=1)]


def _segment_min(values: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    """Minimum of ``values`` per owner id (``owner`` sorted ascending), ``inf`` where none, (n,)."""
    out = np.full(n, np.inf)
    if len(values):
        starts = np.r_[0, np.flatnonzero(np.diff(owner)) + 1]
        out[owner[starts]] = np.minimum.reduceat(values, starts)
    return out


# ------------------------------------------------------------------ the checker
class CollisionChecker:
    """Checks posed grippers against one object and fixed obstacle planes.

    Build it once per (gripper, object) pair (tens of milliseconds); :meth:`check` is then
    cheap: well under a millisecond when the gripper is clear of the object, a few
    milliseconds when it touches or intersects it.

    Args:
        gripper: the gripper; every one of its ``geometries`` is checked.
        obj: the object surface (a mesh or a point cloud with outward normals), object frame.
        obstacles: obstacle half-spaces in the object frame, e.g. ``[Plane.table(z)]``.
        tolerance: penetration depth tolerated before a geometry collides, metres (>= 0).

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
        self.gripper = gripper
        self.object = obj
        self.tolerance = float(tolerance)
        self._model = gripper.model
        self._data = gripper.model.createData()
        rng = np.random.default_rng(0)
        self._build_gripper(gripper, rng)
        self._plane_normals = np.array([p.normal for p in self.obstacles]).reshape(-1, 3)
        self._plane_offsets = np.array([p.offset for p in self.obstacles])

        self._surface, features = _object_model(obj, self.tolerance, rng)
        pts = self._surface.points
        coarse_spacing = max(_OBJECT_COARSE_SPACING, 2 * self._surface.spacing)
        coarse = _voxel_thin(pts, coarse_spacing)
        self._coarse_surface = _SurfaceModel(pts[coarse], self._surface.normals[coarse], coarse_spacing)
        self._coarse_tree = self._coarse_surface.tree
        dist, _ = self._coarse_tree.query(pts, workers=1)
        self._coarse_radius = float(dist.max())
        # Object points searched inside gripper elements (all), and facing their sides (sparse).
        self._probe = _BoxIndex(np.concatenate([pts, features]))
        self._features = _BoxIndex(np.concatenate([pts[coarse], features]))
        self._lo, self._hi = self._probe.points.min(axis=0), self._probe.points.max(axis=0)
        # Readings beyond ``best`` are not needed, but the edge rule needs the samples of the
        # other face, which can lie a few disk radii farther than the nearest one.
        self._reach = 3.0 * _SurfaceModel.disk * self._surface.spacing
        self._coarse_reach = 3.0 * _SurfaceModel.disk * coarse_spacing

    def _build_gripper(self, gripper: Gripper, rng: np.random.Generator) -> None:
        links = list(dict.fromkeys(g.link for g in gripper.geometries))
        missing = [link for link in links if not self._model.existFrame(link)]
        if missing:
            raise GripperDescriptionError(gripper.name, [
                f"a geometry belongs to link {link!r}, which the model lacks; fix its link name"
                for link in missing])
        self._frame_ids = [self._model.getFrameId(link) for link in links]
        built = [_build_element(g, links.index(g.link), rng) for g in gripper.geometries]
        self._elements = [e for e, _ in built]
        # Contact elements: those the contact points of their link lie on (else the whole link).
        for link in dict.fromkeys(s.link for s in gripper.surfaces):
            points = np.concatenate([s.points for s in gripper.surfaces if s.link == link]).astype(float)
            mine = [k for k, e in enumerate(self._elements) if e.link == link]
            hits = [k for k in mine if _lies_on(built[k][1], points)]
            for k in hits or mine:
                self._elements[k].contact = True

        elements = self._elements
        self._hull = np.concatenate([e.hull for e in elements])
        self._hull_frame = np.concatenate([np.full(len(e.hull), e.frame) for e in elements])
        self._hull_start = np.r_[0, np.cumsum([len(e.hull) for e in elements])[:-1]]
        # Every element's points stacked: global ids, owners and coarse cells.
        sizes = np.array([len(e.points) for e in elements])
        self._start = np.r_[0, np.cumsum(sizes)]
        self._points = np.concatenate([e.points for e in elements])
        self._owner = np.repeat(np.arange(len(elements)), sizes)
        self._point_frame = np.repeat([e.frame for e in elements], sizes)
        n_coarse = np.array([len(e.coarse) for e in elements])
        cell_start = np.r_[0, np.cumsum(n_coarse)[:-1]]
        self._coarse = np.concatenate([self._start[k] + e.coarse for k, e in enumerate(elements)])
        self._coarse_owner = np.repeat(np.arange(len(elements)), n_coarse)
        self._cell = np.concatenate([cell_start[k] + e.parent for k, e in enumerate(elements)])
        self._cell_order = np.argsort(self._cell, kind="stable")
        self._cell_start = np.searchsorted(self._cell[self._cell_order], np.arange(len(self._coarse) + 1))
        self._radius = np.array([e.radius for e in elements])
        self._contact = np.array([e.contact for e in elements])
        logger.debug("collision geometry: %s", ", ".join(
            f"{e.name} ({len(e.points)} points{', contact' if e.contact else ''})" for e in elements))

    # ---------------------------------------------------------------- inputs
    def _inputs(self, T_object_gripper, q) -> tuple[np.ndarray, np.ndarray]:
        T = np.asarray(T_object_gripper, dtype=float)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise InvalidInputError(f"T_object_gripper must be a finite 4x4 homogeneous transform, "
                                    f"got shape {T.shape}; pass the fitted palm pose")
        R = T[:3, :3]
        if np.abs(R.T @ R - _EYE).max() > 1e-6 or np.abs(T[3] - _LAST_ROW).max() > 1e-12:
            raise InvalidInputError("T_object_gripper is not a rigid transform (rotation not "
                                    "orthonormal or last row not [0 0 0 1]); re-orthonormalise it")
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self._model.nq,) or not np.isfinite(q).all():
            raise InvalidInputError(f"q must hold {self._model.nq} finite joint values "
                                    f"({', '.join(self.gripper.joint_names)}), got shape {q.shape}")
        return T, q

    def _link_poses(self, T: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (L, 3, 3) and translations (L, 3) of the checked links in the object frame."""
        pin.framesForwardKinematics(self._model, self._data, q)
        H = T @ np.stack([self._data.oMf[fid].homogeneous for fid in self._frame_ids])
        return H[:, :3, :3], H[:, :3, 3]

    def _posed(self, ids: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Object-frame positions (M, 3) of the stacked element points ``ids``."""
        f = self._point_frame[ids]
        return np.einsum("nij,nj->ni", R[f], self._points[ids]) + t[f]

    # ---------------------------------------------------------------- check
    def check(self, T_object_gripper: np.ndarray, q: np.ndarray) -> CollisionReport:
        """Check the gripper at palm pose ``T_object_gripper`` (4, 4) and joints ``q`` (n_joints,).

        Returns:
            the :class:`CollisionReport`.

        Raises:
            InvalidInputError: ``T_object_gripper`` is not a rigid 4x4 transform or ``q`` has the
                wrong length or non-finite values.
        """
        T, q = self._inputs(T_object_gripper, q)
        R, t = self._link_poses(T, q)
        n = len(self._elements)
        hull = np.einsum("nij,nj->ni", R[self._hull_frame], self._hull) + t[self._hull_frame]
        lo = np.minimum.reduceat(hull, self._hull_start, axis=0)
        hi = np.maximum.reduceat(hull, self._hull_start, axis=0)

        depth, where, best = np.zeros(n), np.full(n, -1), np.inf  # where: -1 object, k plane k
        if len(self.obstacles):
            heights = np.minimum.reduceat(hull @ self._plane_normals.T - self._plane_offsets,
                                          self._hull_start, axis=0)  # (E, P)
            worst = heights.argmin(axis=1)
            depth = np.maximum(0.0, -heights[np.arange(n), worst])
            where = np.where(depth > 0, worst, -1)
            best = float(heights.min())

        gap = np.maximum(self._lo - hi, 0.0) + np.maximum(lo - self._hi, 0.0)
        box_distance = np.linalg.norm(gap, axis=1)  # element AABB to object AABB
        done = np.zeros(len(self._points), dtype=bool)
        near = np.flatnonzero(box_distance == 0.0)
        if len(near):
            best = self._penetration(near, R, t, lo, hi, depth, where, done, best)
        best = self._clearance(box_distance, R, t, lo, hi, done, best)
        return self._report(depth, where, best)

    def _penetration(self, near, R, t, lo, hi, depth, where, done, best: float) -> float:
        """Object penetration of the elements ``near`` the object (updates depth, where, done).

        Returns:
            ``best`` lowered to the smallest reading of a non-contact element.
        """
        ids = np.concatenate([np.arange(self._start[k], self._start[k + 1]) for k in near])
        posed = self._posed(ids, R, t)
        inside = np.all((posed >= self._lo) & (posed <= self._hi), axis=1)
        ids, posed = ids[inside], posed[inside]
        done[ids] = True
        reading = self._surface.signed_distance(posed, bound=_DEEP)
        deep = ~np.isfinite(reading)  # no sample within _DEEP: read on the coarse subset
        if deep.any():
            reading[deep] = self._coarse_surface.signed_distance(posed[deep])
        lowest = _segment_min(reading, self._owner[ids], len(self._elements))
        for k in near:
            e = self._elements[k]
            d = max(0.0, -lowest[k]) if np.isfinite(lowest[k]) else 0.0
            if e.closed:
                d = max(d, self._object_inside(e, R[e.frame], t[e.frame], lo[k], hi[k]))
            if d > depth[k]:
                depth[k], where[k] = d, -1
            if not e.contact:
                best = min(best, lowest[k])
        return best

    def _object_inside(self, e: _Element, R: np.ndarray, t: np.ndarray, lo: np.ndarray,
                       hi: np.ndarray) -> float:
        """Deepest object probe point inside element ``e`` (posed by R, t), metres."""
        pts = self._probe.inside(lo, hi)
        return e.depth_of((pts - t) @ R) if len(pts) else 0.0

    def _clearance(self, box_distance, R, t, lo, hi, done, best: float) -> float:
        """Smallest distance of a non-contact element to the object, at most ``best``.

        Coarse to fine: each element's coarse points against the coarse object subset first;
        only the cells that may hold something closer than the best so far are read point by
        point, within ``_NEAR`` on the full object samples, within ``_FAR`` on the coarse ones.
        """
        cand = np.flatnonzero(~self._contact & (box_distance - self._surface.spacing < best))
        if not len(cand):
            return best
        mask = np.zeros(len(self._elements), dtype=bool)
        mask[cand] = True
        cells = np.flatnonzero(mask[self._coarse_owner])
        ids = self._coarse[cells]
        posed = self._posed(ids, R, t)
        far, _ = self._coarse_tree.query(posed, workers=1)  # distance to a coarse sample
        best = min(best, float(far.min()))
        if best > _FAR:
            return best
        radius = self._radius[self._coarse_owner[cells]]
        lower = far - self._coarse_radius  # lower bound of each coarse point's distance
        read = (lower - radius < best) & ~done[ids]
        if read.any():
            lower[read] = self._read(posed[read], lower[read], best)
            best = min(best, float(lower[read].min()))
        done[ids] = True
        refine = np.flatnonzero(lower - radius - self._surface.spacing < best)
        if len(refine):
            ids, which = self._members(cells[refine], done)
            if len(ids):
                estimate = lower[refine][which]
                best = min(best, float(self._read(self._posed(ids, R, t), estimate, best).min()))
        reach = min(best, _NEAR)
        for k in cand[np.argsort(box_distance[cand])]:
            if box_distance[k] >= reach:
                break
            e = self._elements[k]
            if e.planes is not None:  # object features facing a flat side of a convex element
                pts = self._features.inside(lo[k] - reach, hi[k] + reach)
                if len(pts):
                    best = min(best, float(e.face_distance((pts - t[e.frame]) @ R[e.frame]).min()))
                    reach = min(best, _NEAR)
        return best

    def _read(self, points: np.ndarray, estimate: np.ndarray, best: float) -> np.ndarray:
        """Distance readings of points whose distance is about ``estimate``: on the full object
        samples within ``_NEAR``, on the coarse subset beyond."""
        out = np.empty(len(points))
        fine = estimate <= _NEAR
        if fine.any():
            out[fine] = self._surface.signed_distance(points[fine], bound=best + self._reach)
        if not fine.all():
            out[~fine] = self._coarse_surface.signed_distance(points[~fine], bound=best + self._coarse_reach)
        return out

    def _members(self, cells: np.ndarray, done: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stacked ids of the points of coarse ``cells`` not yet read, and the index into
        ``cells`` of each."""
        parts = [self._cell_order[self._cell_start[c]:self._cell_start[c + 1]] for c in cells]
        ids = np.concatenate(parts)
        which = np.repeat(np.arange(len(cells)), [len(part) for part in parts])
        keep = ~done[ids]
        return ids[keep], which[keep]

    def _report(self, depth: np.ndarray, where: np.ndarray, clearance: float) -> CollisionReport:
        colliding = depth > self.tolerance
        links = tuple(dict.fromkeys(self._elements[k].link for k in np.flatnonzero(colliding)))
        obstacle = None
        if colliding.any():
            k = int(np.argmax(depth))
            obstacle = "object" if where[k] < 0 else self.obstacles[where[k]].name
        return CollisionReport(collision_free=not colliding.any(), penetration=float(depth.max()),
                               clearance=max(0.0, float(clearance)), colliding_links=links,
                               obstacle=obstacle)
