"""Gripper geometry elements prepared for collision checks: surface samples in patches.

An element (one :class:`~isf.gripper.model.LinkGeometry`) carries, in its link frame:

* surface samples: area-uniform points (1 mm apart, at most 800) plus the mesh vertices;
* *patches*: a few dozen of the samples are patch centres (one per cell of a voxel grid sized
  for :data:`PATCH_COUNT` centres, plus the last vertex); every sample belongs to the nearest
  centre and stores its offset from it. A check evaluates the object's signed distance exactly
  at the centres only and predicts it at the other samples to first order (see
  :mod:`isf.collision.checker`);
* its convex hull (vertices and face planes), bounding sphere and mesh; for a closed element
  the description of its inside (face planes when convex, else a tangent-plane surface and a
  grid of its estimate), with compiled tests of object points inside it
  (:func:`convex_depth`, :func:`non_convex_depth`) and exact point-triangle distances.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..compiled.kernels import kernel
from ..gripper.model import LinkGeometry
from ..search.nearest import search_scratch
from .surface_distance import NEIGHBOURS, TangentPlanes, estimate

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


@kernel(inline=True)
def _segment_distance2(px, py, pz, ax, ay, az, bx, by, bz):
    """Squared distance from ``p`` to the segment ``ab``."""
    dx, dy, dz = bx - ax, by - ay, bz - az
    length2 = dx * dx + dy * dy + dz * dz
    s = 0.0 if length2 <= 0.0 else min(max(((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / length2, 0.0), 1.0)
    return (px - ax - s * dx) ** 2 + (py - ay - s * dy) ** 2 + (pz - az - s * dz) ** 2


@kernel(inline=True)
def triangle_distance2(px, py, pz, tri, f):
    """Squared distance from ``p`` to triangle ``tri[f]`` ((F, 3, 3) corners): the nearest point
    by the triangle's Voronoi regions (Ericson, Real-Time Collision Detection, 5.1.5); a
    degenerate triangle's by its edges."""
    ax, ay, az = tri[f, 0, 0], tri[f, 0, 1], tri[f, 0, 2]
    bx, by, bz = tri[f, 1, 0], tri[f, 1, 1], tri[f, 1, 2]
    cx, cy, cz = tri[f, 2, 0], tri[f, 2, 1], tri[f, 2, 2]
    abx, aby, abz, acx, acy, acz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
    d1 = abx * (px - ax) + aby * (py - ay) + abz * (pz - az)
    d2 = acx * (px - ax) + acy * (py - ay) + acz * (pz - az)
    d3 = abx * (px - bx) + aby * (py - by) + abz * (pz - bz)
    d4 = acx * (px - bx) + acy * (py - by) + acz * (pz - bz)
    d5 = abx * (px - cx) + aby * (py - cy) + abz * (pz - cz)
    d6 = acx * (px - cx) + acy * (py - cy) + acz * (pz - cz)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    if va > 0.0 and vb > 0.0 and vc > 0.0:  # the foot lies inside: the distance to the plane
        v, w = vb / (va + vb + vc), vc / (va + vb + vc)
        return ((px - ax - v * abx - w * acx) ** 2 + (py - ay - v * aby - w * acy) ** 2
                + (pz - az - v * abz - w * acz) ** 2)
    return min(_segment_distance2(px, py, pz, ax, ay, az, bx, by, bz),
               _segment_distance2(px, py, pz, bx, by, bz, cx, cy, cz),
               _segment_distance2(px, py, pz, cx, cy, cz, ax, ay, az))


@kernel
def _nearest_triangle_distances(points, triangles):
    out = np.empty(len(points))
    for i in range(len(points)):
        best = np.inf
        for f in range(len(triangles)):
            best = min(best, triangle_distance2(points[i, 0], points[i, 1], points[i, 2], triangles, f))
        out[i] = np.sqrt(best)
    return out


def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Exact distance of each point (M, 3) to the nearest of the triangles (F, 3, 3), metres (M,)."""
    return _nearest_triangle_distances(np.ascontiguousarray(points, dtype=np.float64),
                                       np.ascontiguousarray(triangles, dtype=np.float64))


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


@kernel(inline=True)
def _above(x, y, z, planes):
    """Largest signed distance of ``(x, y, z)`` to the planes ``[n, n . x]`` (F, 4); -inf for none."""
    sd = -np.inf
    for f in range(len(planes)):
        sd = max(sd, x * planes[f, 0] + y * planes[f, 1] + z * planes[f, 2] - planes[f, 3])
    return sd


@kernel(inline=True)
def _node_value(values, lo, h, x, y, z):
    """``values`` (grid with corner ``lo``, spacing ``h``) at the node nearest ``(x, y, z)``; inf
    off the grid."""
    a = np.rint((x - lo[0]) / h)
    b = np.rint((y - lo[1]) / h)
    c = np.rint((z - lo[2]) / h)
    if 0 <= a < values.shape[0] and 0 <= b < values.shape[1] and 0 <= c < values.shape[2]:
        return values[int(a), int(b), int(c)]
    return np.inf


@kernel(inline=True)
def _in_box(points, i, pose, bounds):
    """Point ``i`` of ``points`` (M, 3) in the frame ``pose`` (4, 4) places, and whether it lies
    in the box ``bounds`` (2, 3) there."""
    x, y, z = points[i, 0] - pose[0, 3], points[i, 1] - pose[1, 3], points[i, 2] - pose[2, 3]
    a = x * pose[0, 0] + y * pose[1, 0] + z * pose[2, 0]
    b = x * pose[0, 1] + y * pose[1, 1] + z * pose[2, 1]
    c = x * pose[0, 2] + y * pose[1, 2] + z * pose[2, 2]
    inside = (bounds[0, 0] <= a <= bounds[1, 0] and bounds[0, 1] <= b <= bounds[1, 1]
              and bounds[0, 2] <= c <= bounds[1, 2])
    return a, b, c, inside


@kernel
def convex_depth(points, pose, bounds, planes):
    """Deepest of the object points (M, 3), object frame, inside a convex element posed at
    ``pose`` (4, 4) with link-frame box ``bounds`` (2, 3) and face planes ``planes`` (F, 4) as
    ``[n, n . x]`` rows, metres (0 if none): exact."""
    low = np.inf
    for i in range(len(points)):
        a, b, c, inside = _in_box(points, i, pose, bounds)
        if inside:
            low = min(low, _above(a, b, c, planes))
    return max(0.0, -low)


@kernel
def non_convex_depth(points, pose, bounds, tolerance, hull_planes, field, field_lo, field_h,
                     surface_points, surface_normals, tree, neighbours):
    """Deepest of the object points (M, 3), object frame, inside a closed non-convex element
    posed at ``pose`` (4, 4), metres (0 if none).

    Points outside its link-frame box ``bounds`` (2, 3) or its convex hull (face planes
    ``hull_planes`` (G, 4); none when G = 0) are outside; the rest get the tangent-plane estimate
    of its surface (``surface_points``, ``surface_normals`` (N, 3), their ``tree``
    (:class:`isf.search.kdtree.KDTree`), ``neighbours``): all of them when few, else those
    its grid (``field`` values at nodes ``field_lo + field_h * index``, see
    :class:`SignedDistanceGrid`) finds deepest (the ``_FIELD_DEEPEST`` deepest-looking, ties to
    the earlier point) or possibly deeper than ``tolerance``.
    """
    local = np.empty((len(points), 3))
    n = 0
    for i in range(len(points)):
        a, b, c, inside = _in_box(points, i, pose, bounds)
        if inside and (not len(hull_planes) or _above(a, b, c, hull_planes) < 0):
            local[n, 0], local[n, 1], local[n, 2] = a, b, c
            n += 1
    keep = np.ones(n, np.bool_)
    if n > _FIELD_FROM:  # screen: the deepest-looking points and any that may be too deep
        value = np.empty(n)
        top = np.empty(_FIELD_DEEPEST, np.int64)
        found = 0
        for i in range(n):
            value[i] = _node_value(field, field_lo, field_h, local[i, 0], local[i, 1], local[i, 2])
            keep[i] = value[i] < field_h - tolerance
            if not value[i] < field_h or (found == _FIELD_DEEPEST and value[i] >= value[top[found - 1]]):
                continue
            j = min(found, _FIELD_DEEPEST - 1)
            while j > 0 and value[top[j - 1]] > value[i]:
                top[j] = top[j - 1]
                j -= 1
            top[j] = i
            found = min(found + 1, _FIELD_DEEPEST)
        for j in range(found):
            keep[top[j]] = True
    stack = search_scratch()
    best_d2, best = np.empty(neighbours), np.empty(neighbours, np.int64)
    depth = 0.0
    for i in range(n):
        if keep[i]:
            sd, _, _, _ = estimate(local[i, 0], local[i, 1], local[i, 2], best_d2, best,
                                   surface_points, surface_normals, tree, stack)
            depth = max(depth, -sd)
    return depth


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
        surface: tangent planes of a closed non-convex element's surface, else None; ``field``:
            their :class:`SignedDistanceGrid` over its bounds, else None.
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
        self.contact = False
        self.field = None if self.surface is None else SignedDistanceGrid(self.surface, self.bounds)

    def object_depth(self, points: np.ndarray, T_object_element: np.ndarray, tolerance: float) -> float:
        """Deepest of the object points (M, 3), object frame, inside this element posed at
        ``T_object_element`` (4, 4), metres (0 if none or not closed): :func:`convex_depth` or
        :func:`non_convex_depth`."""
        if not self.closed:
            return 0.0
        points = np.ascontiguousarray(points, dtype=np.float64)
        pose = np.ascontiguousarray(T_object_element, dtype=np.float64)
        if self.planes is not None:
            return convex_depth(points, pose, self.bounds, self.planes)
        hull = self.hull_planes if self.hull_planes is not None else np.empty((0, 4))
        s, f = self.surface, self.field
        return non_convex_depth(points, pose, self.bounds, tolerance, hull, f.values, f.lo, f.h, s.points,
                                s.normals, s.tree.tree.kd, min(NEIGHBOURS, len(s.points)))


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
