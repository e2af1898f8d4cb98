"""Gripper geometry elements prepared for collision checks: surface samples in patches.

An element (one :class:`~isf.gripper.LinkGeometry`) carries, in its link frame:

* surface samples: area-uniform points (1 mm apart, at most 800) plus the mesh vertices;
* *patches*: a few dozen of the samples are patch centres (one per cell of a voxel grid sized
  for :data:`PATCH_COUNT` centres, plus the last vertex); every sample belongs to the nearest
  centre and stores its offset from it. A check evaluates the object's signed distance exactly
  at the centres only and predicts it at the other samples to first order (see
  :mod:`isf.collision`);
* its convex hull (vertices and face planes), bounding sphere and coal BVH; for a closed element
  the description of its inside (face planes when convex, else a tangent-plane surface).
"""

from __future__ import annotations

import coal
import numpy as np
import trimesh
from numba import njit
from scipy.spatial import cKDTree

from .collision_surface import TangentPlanes
from .gripper import LinkGeometry

SAMPLE_SPACING = 0.001  # gripper surface samples, m
MAX_SAMPLES = 800  # per element (spacing grows on large elements)
PATCH_COUNT = 24  # patch centres aimed at per element
_FIELD_FROM = 32  # object points to test inside a non-convex element before a grid screens them
_FIELD_DEEPEST = 16


def even_samples(mesh: trimesh.Trimesh, spacing: float, max_points: int,
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


def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
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


def bvh(vertices: np.ndarray, faces: np.ndarray) -> coal.BVHModelOBBRSS:
    """A coal BVH of a triangle mesh."""
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(faces), len(vertices))
    model.addVertices(np.ascontiguousarray(vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(faces, dtype=np.int64))
    model.endModel()
    return model


def patches(samples: np.ndarray, area: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Patch centres among ``samples`` (N, 3) and each sample's centre.

    One centre per occupied cell of a voxel grid with about ``count`` cells on a surface of
    ``area`` m^2 (the sample nearest the cell's middle), plus the last sample.

    Returns:
        (indices of the centres (C,), index into the centres of each sample's nearest one (N,)).
    """
    cell = max(np.sqrt(area / count), 1e-6)
    keys = np.floor(samples / cell).astype(np.int64)
    off = np.linalg.norm(samples - (keys + 0.5) * cell, axis=1)
    order = np.lexsort((off, keys[:, 2], keys[:, 1], keys[:, 0]))
    sorted_keys = keys[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = np.any(sorted_keys[1:] != sorted_keys[:-1], axis=1)
    centres = np.union1d(order[first], [len(samples) - 1])
    _, nearest = cKDTree(samples[centres]).query(samples, workers=1)
    nearest[centres] = np.arange(len(centres))  # ties: a centre is its own
    return centres, nearest


@njit(cache=True, error_model="numpy")
def _in_box(points, R, t, lo, hi):
    """The points (M, 3) that ``(p - t) @ R`` maps into the box [lo, hi], so mapped (K, 3)."""
    out = np.empty((len(points), 3))
    k = 0
    for i in range(len(points)):
        x, y, z = points[i, 0] - t[0], points[i, 1] - t[1], points[i, 2] - t[2]
        inside = True
        for d in range(3):
            out[k, d] = x * R[0, d] + y * R[1, d] + z * R[2, d]
            inside = inside and lo[d] <= out[k, d] <= hi[d]
        k += inside
    return out[:k]


@njit(cache=True, error_model="numpy")
def _above_planes(local, planes):
    """Largest signed distance of each point (M, 3) to the planes ``[n, n . x]`` (F, 4), (M,)."""
    out = np.empty(len(local))
    for i in range(len(local)):
        sd = -np.inf
        for f in range(len(planes)):
            sd = max(sd, local[i, 0] * planes[f, 0] + local[i, 1] * planes[f, 1]
                     + local[i, 2] * planes[f, 2] - planes[f, 3])
        out[i] = sd
    return out


@njit(cache=True, error_model="numpy")
def _at_nearest_node(values, lo, h, points):
    """``values`` (grid with corner ``lo``, spacing ``h``) at each point's (M, 3) nearest node,
    (M,); inf off the grid."""
    out = np.empty(len(points))
    for i in range(len(points)):
        out[i] = np.inf
        a = np.rint((points[i, 0] - lo[0]) / h)
        b = np.rint((points[i, 1] - lo[1]) / h)
        c = np.rint((points[i, 2] - lo[2]) / h)
        if 0 <= a < values.shape[0] and 0 <= b < values.shape[1] and 0 <= c < values.shape[2]:
            out[i] = values[int(a), int(b), int(c)]
    return out


class Element:
    """One gripper geometry element, precomputed in its link frame.

    Attributes:
        link, name: the geometry's link and name.
        frame: index of its link among the checker's links.
        samples: surface samples then mesh vertices, (N, 3); the last one is a vertex.
        centres: indices of the patch centres in ``samples``, (C,); includes N - 1.
        parent: index into ``centres`` of each sample's patch, (N,).
        hull: convex-hull vertices, (H, 3); ``hull_planes``: its outward face planes (F, 4)
            as ``[n, n . x]`` rows (None when qhull failed).
        centre, radius: bounding sphere of the hull.
        closed: a closed, consistently wound mesh (it has an inside).
        bounds: its bounding box, (2, 3) as [lower, upper] corners.
        planes: outward face planes (F, 4) of a closed convex element, else None.
        surface: tangent planes of a closed non-convex element's surface, else None.
        contact: some contact-surface point of its link lies on it (set by the checker).
    """

    def __init__(self, geom: LinkGeometry, frame: int, rng: np.random.Generator):
        self.link, self.name, self.frame = geom.link, geom.name, frame
        mesh = trimesh.Trimesh(np.asarray(geom.vertices, float), np.asarray(geom.faces, np.int64),
                               process=True, validate=False)
        self.mesh = mesh
        self.bounds = np.array(mesh.bounds, dtype=float)
        self.hull_planes = None
        try:
            with np.errstate(invalid="ignore", divide="ignore"):  # flat sheets: zero hull volume
                hull = mesh.convex_hull
                self.hull = np.asarray(hull.vertices, dtype=float)
                if hull.is_watertight and hull.volume > 0:
                    n = hull.face_normals
                    self.hull_planes = np.c_[n, np.einsum("ij,ij->i", n, hull.triangles[:, 0])]
        except Exception:  # qhull fails on flat or degenerate geometry
            self.hull = np.asarray(mesh.vertices, dtype=float)
        lo, hi = self.hull.min(axis=0), self.hull.max(axis=0)
        self.centre = (lo + hi) / 2
        self.radius = float(np.linalg.norm(self.hull - self.centre, axis=1).max())
        samples, normals = even_samples(mesh, SAMPLE_SPACING, MAX_SAMPLES, rng)
        self.samples = np.concatenate([samples, mesh.vertices])
        self.centres, self.parent = patches(self.samples, float(mesh.area), PATCH_COUNT)
        self.closed = bool(mesh.is_watertight and mesh.is_winding_consistent)
        self.planes = None
        self.surface = None
        if self.closed:  # to find object points inside the element
            sign = np.sign(mesh.volume)
            if mesh.is_convex:  # exact: the largest signed distance to its face planes
                n = sign * mesh.face_normals
                self.planes = np.c_[n, np.einsum("ij,ij->i", n, mesh.triangles[:, 0])]
            else:
                self.surface = TangentPlanes(samples, normals * sign, np.sqrt(mesh.area / len(samples)))
        self.bvh = bvh(mesh.vertices, mesh.faces)
        self.contact = False
        self._field: SignedDistanceGrid | None = None  # built on first need

    def object_depth(self, points: np.ndarray, T_object_element: np.ndarray,
                     tolerance: float) -> float:
        """Deepest of the object points (M, 3), object frame, inside this closed element posed at
        ``T_object_element`` (4, 4), metres (0 if none): :meth:`depth_of` of those in its box."""
        if not self.closed:
            return 0.0
        R, t = T_object_element[:3, :3], T_object_element[:3, 3]
        local = _in_box(points, R, t, self.bounds[0], self.bounds[1])
        return self.depth_of(local, tolerance)

    def depth_of(self, local: np.ndarray, tolerance: float) -> float:
        """Deepest of the points (M, 3), link frame, inside this closed element, metres (0 if none).

        Exact by the face planes when the element is convex; else points outside its convex
        hull are outside, and the rest get the tangent-plane estimate of its surface: all of them
        when few, else those a grid of that estimate finds deepest (the ``_FIELD_DEEPEST``
        deepest-looking) or possibly deeper than ``tolerance``.
        """
        if not self.closed or len(local) == 0:
            return 0.0
        if self.planes is not None:
            return float(max(0.0, -_above_planes(local, self.planes).min()))
        if self.hull_planes is not None:
            local = local[_above_planes(local, self.hull_planes) < 0]
        if len(local) > _FIELD_FROM:  # screen: the deepest-looking points and any that may be too deep
            if self._field is None:
                self._field = SignedDistanceGrid(self.surface, self.bounds)
            value = self._field.interpolate(local)
            maybe = np.flatnonzero(value < self._field.h)
            top = maybe[np.argsort(value[maybe])[:_FIELD_DEEPEST]]
            local = local[np.union1d(top, maybe[value[maybe] < self._field.h - tolerance])]
        return self.surface.depth(local)


class SignedDistanceGrid:
    """The tangent-plane signed distance of a surface sampled on a grid over its bounds.

    The value at the nearest node screens query points: one whose value there exceeds the grid
    spacing ``h`` (more than the error of a 1-Lipschitz distance half a cell diagonal away) lies
    outside.
    """

    def __init__(self, surface: TangentPlanes, bounds: np.ndarray, nodes: int = 8000):
        lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
        h = max(5e-4, float(np.prod(hi - lo + 4e-3) / nodes) ** (1 / 3))
        self.h, self.lo = h, lo - 2 * h
        self.shape = np.ceil((hi + 2 * h - self.lo) / h).astype(int) + 1
        axes = [self.lo[k] + h * np.arange(self.shape[k]) for k in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        self.values = surface.signed_distance(grid).reshape(self.shape)

    def interpolate(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of points (M, 3) at their nearest grid node, metres (M,); inf outside
        the grid. Off by at most ``h`` (half a cell diagonal, for a 1-Lipschitz distance)."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        return _at_nearest_node(self.values, self.lo, self.h, points)
