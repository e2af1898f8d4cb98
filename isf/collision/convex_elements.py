"""The closed convex geometry elements of a gripper, and the object points inside them.

The collision repair (:mod:`isf.repair.clearance`) samples every link's geometry, but an object
edge can poke into a link between its samples. For a closed convex element the test is
exact: a point lies inside when it is below every face plane ``n . x <= d``. The repair
pushes such points (and those within a reach of the element) out through the element's
nearest face. :meth:`ConvexElements.rows` finds them for all elements at once, in compiled
code: the object points within each element's bounding sphere and within the box (in its link
frame) of the points less than the reach above every face plane (found through a
:class:`isf.search.point_grid.PointGrid`), then its faces in spread-out order, up to the first that
leaves the point out.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import trimesh
from scipy.spatial import HalfspaceIntersection, QhullError

from ..compiled.arrays import copy_into
from ..compiled.kernels import kernel
from ..search.kdtree import squared_distance
from ..search.point_grid import PointGrid, ball_box_candidates

__all__ = ["ConvexElements", "ConvexRows", "ConvexShapes"]

MAX_PLANES = 128
"""Face planes kept per element (spread-out normals): a subset of a convex element's face
planes bounds a slightly larger polytope, which errs on the safe side and keeps a finely
tessellated sphere cheap (1280 faces -> 128 planes: ~0.2 mm larger at 12 mm)."""


class ConvexShapes(NamedTuple):
    """The convex elements' shapes, C elements, link frames."""

    centres: np.ndarray
    """Inner points (the vertices' mean), (C, 3) float64, m."""
    radii: np.ndarray
    """Radii of the balls about them that hold the elements, (C,) float64, m."""
    extents: np.ndarray
    """How deep a point may lie in each element (:func:`_extent`), (C,) float64, m."""
    floors: np.ndarray
    """The rows' floors, (C,) float64, m."""
    planes: np.ndarray
    """Outward face planes ``[n, d]``, (P, 4) float64; element ``c``'s are
    ``plane_start[c]:plane_start[c + 1]``."""
    plane_start: np.ndarray
    """(C + 1,) int64."""


class ConvexRows(NamedTuple):
    """Object points inside (or within reach of) convex elements, one row each.

    Attributes:
        element: index of the element into :attr:`ConvexElements.element`, (K,).
        foot: where the point must leave the element (on its nearest face), link frame, (K, 3).
        normal: that face's inward normal in the object frame (the direction the element must
            move for the point to leave it), (K, 3).
        depth: signed distance of the point above that face plane (negative inside), (K,), m.
        point: index of the object point, (K,).
    """

    element: np.ndarray
    foot: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    point: np.ndarray


@kernel
def _spread(directions, count):
    """Indices (at most ``count``) of rows of ``directions`` (N, 3) in farthest-point order."""
    n = len(directions)
    if n <= count:
        return np.arange(n)
    chosen = np.empty(count, np.int64)
    chosen[0] = 0
    gap = np.empty(n)
    for i in range(n):
        gap[i] = _distance(directions, i, 0)
    for c in range(1, count):
        k = np.argmax(gap)
        chosen[c] = k
        for i in range(n):
            gap[i] = min(gap[i], _distance(directions, i, k))
    return chosen


@kernel(inline=True)
def _distance(points, i, j):
    """Distance between rows ``i`` and ``j`` of ``points`` (N, 3)."""
    return np.sqrt(squared_distance(points, i, points[j, 0], points[j, 1], points[j, 2]))


class _Faces(NamedTuple):
    """A closed convex mesh's face planes and bounds (:func:`_face_planes`)."""

    planes: np.ndarray
    """Outward face planes ``[n, d]`` (P, 4), spread-out order."""
    centre: np.ndarray
    """The vertices' mean, (3,), m."""
    radius: float
    """Distance from the centre to the farthest vertex, m."""
    extent: float
    """:func:`_extent` of the planes, m."""


def _face_planes(vertices: np.ndarray, faces: np.ndarray) -> _Faces | None:
    """The :class:`_Faces` of a closed convex mesh, or None when the mesh is not one."""
    mesh = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces, np.int64))
    if not (len(mesh.faces) and mesh.is_watertight and mesh.is_winding_consistent and
            mesh.is_convex):
        return None
    n = np.sign(mesh.volume) * mesh.face_normals
    kept = _spread(n, MAX_PLANES)
    planes = np.c_[n, np.einsum("ij,ij->i", n, mesh.triangles[:, 0])][kept]
    centre = mesh.vertices.mean(axis=0)
    radius = float(np.linalg.norm(mesh.vertices - centre, axis=1).max())
    return _Faces(planes, centre, radius, _extent(planes, centre, radius, len(kept) < len(n)))


def _extent(planes: np.ndarray, centre: np.ndarray, radius: float, dropped: bool) -> float:
    """Largest distance from ``centre`` (3,), an inner point, of the polytope ``n . x <= d`` of
    ``planes`` (P, 4), padded for rounding: the element's ``radius`` when no face plane was
    ``dropped``, else from the polytope's corners (inf when it is unbounded or qhull fails)."""
    if dropped:
        try:
            halfspaces = np.c_[planes[:, :3], -planes[:, 3]]
            corners = HalfspaceIntersection(halfspaces, centre).intersections
        except QhullError:
            return np.inf
        if not np.all(np.isfinite(corners)):
            return np.inf
        radius = float(np.linalg.norm(corners - centre, axis=1).max())
    return radius * (1.0 + 1e-9) + 1e-12


class ConvexElements:
    """The closed convex elements among a gripper's link geometries, in their link frames.

    Args:
        geometries: (vertices, faces) of every geometry element.
        owner: link index (into the caller's link poses) of every element, (E,).
        floor: the depth each element's points may keep, per element, (E,), m (see
            :class:`isf.repair.clearance.RepairConfig`).

    Attributes:
        element: indices (C,) of the convex elements among the geometries.
        owner, floor: theirs, (C,).
    """

    def __init__(self, geometries, owner: np.ndarray, floor: np.ndarray):
        of_mesh, found = {}, []  # grippers repeat meshes (fingers): each is examined once
        for e, (v, faces) in enumerate(geometries):
            key = (np.asarray(v, float).tobytes(), np.asarray(faces, np.int64).tobytes())
            if key not in of_mesh:
                of_mesh[key] = _face_planes(v, faces)
            if of_mesh[key] is not None:
                found.append((e, of_mesh[key]))
        self.element = np.array([e for e, _ in found], dtype=np.int64)
        self.owner = np.asarray(owner, dtype=np.int64)[self.element]
        self.floor = np.asarray(floor, dtype=float)[self.element]
        sizes = [len(f.planes) for _, f in found]
        self._plane_start = np.r_[0, np.cumsum(sizes)].astype(np.int64)
        self._planes = np.concatenate([f.planes for _, f in found]) if found else np.zeros((0, 4))
        self._centre = np.array([f.centre for _, f in found]).reshape(-1, 3)
        self._radius = np.array([f.radius for _, f in found])
        # of the polytope of the kept planes (larger than the element when planes were dropped)
        self._extent = np.array([f.extent for _, f in found])
        self._boxes: dict[float, np.ndarray] = {}  # reach -> _reach_box of every element

    def __len__(self) -> int:
        return len(self.element)

    def rows(self, T: np.ndarray, R: np.ndarray, p: np.ndarray, grid: PointGrid, reach: float,
             keep: int) -> ConvexRows:
        """The object points of ``grid`` inside, or within ``reach`` (m) beyond the floor of, each
        element, with the gripper at palm pose ``T`` (4, 4) and link poses ``R`` (L, 3, 3), ``p``
        (L, 3) (gripper frame); of an element's points, its ``keep`` deepest (largest
        violations ``floor - depth``) and those tied with the last of them. Rows come element
        by element, points in index order."""
        R_links = T[:3, :3] @ R[self.owner]  # element (link) rotations in the object frame
        origins = p[self.owner] @ T[:3, :3].T + T[:3, 3]
        boxes = self._reach_boxes(float(reach))
        shapes = ConvexShapes(self._centre, self._radius, self._extent, self.floor, self._planes,
                              self._plane_start)
        return ConvexRows(*_rows(grid.points, grid.arrays, R_links, origins, shapes, boxes,
                                 float(reach), int(keep)))

    def _reach_boxes(self, reach: float) -> np.ndarray:
        """:func:`_reach_box` of every element for ``reach`` (C, 2, 3), computed once per reach
        (threads that race here compute the same boxes)."""
        boxes = self._boxes.get(reach)
        if boxes is None:
            boxes = np.empty((len(self), 2, 3))
            for c in range(len(self)):
                planes = self._planes[self._plane_start[c]:self._plane_start[c + 1]]
                boxes[c] = _reach_box(planes, self._centre[c], max(self.floor[c] + reach, 0.0))
            self._boxes[reach] = boxes
        return boxes


def _reach_box(planes: np.ndarray, centre: np.ndarray, margin: float) -> np.ndarray:
    """Corners ``[lo, hi]`` (2, 3), link frame, of a box holding every point less than ``margin``
    (m, >= 0) above all the face planes ``n . x <= d`` (P, 4) of a polytope with the inner point
    ``centre`` (3,): the box of the corners of the planes moved out by ``margin``, padded for
    rounding; the whole space when qhull cannot tell (an unbounded polytope)."""
    unique = np.unique(np.round(planes, 12), axis=0)  # a box's two triangles per side: one plane
    try:
        corners = HalfspaceIntersection(np.c_[unique[:, :3], -(unique[:, 3] + margin)],
                                        centre).intersections
    except QhullError:
        corners = np.array([[np.inf] * 3])
    if not np.all(np.isfinite(corners)):
        return np.array([[-np.inf] * 3, [np.inf] * 3])
    pad = 1e-9 * (1.0 + np.abs(corners).max())
    return np.array([corners.min(axis=0) - pad, corners.max(axis=0) + pad])


@kernel
def _rows(points, cells, R_links, origins, shapes, boxes, reach, keep):
    """:meth:`ConvexElements.rows`, compiled: (element (K,), foot (K, 3), normal (K, 3), depth
    (K,), point (K,)) of the object points (N, 3) in their grid ``cells``
    (:class:`isf.search.point_grid.GridCells`) and the elements ``shapes`` (:class:`ConvexShapes`)
    at rotations ``R_links`` (C, 3, 3) and origins ``origins`` (C, 3), object frame. An element's
    candidates are the points in its ball that lie in its reach box (``boxes`` (C, 2, 3),
    :func:`_reach_box`; a point outside it is at least the reach above some face plane). They
    are tried nearest to its centre first (likely the deepest), so that the points shallower
    than ``keep`` rows found are soon skipped; rows found before ``keep`` deeper ones are
    dropped at the end, so the rows do not depend on the order."""
    centres, radii, extents, floors = shapes.centres, shapes.radii, shapes.extents, shapes.floors
    planes, plane_start = shapes.planes, shapes.plane_start
    capacity = 256
    element, foot = np.empty(capacity, np.int64), np.empty((capacity, 3))
    normal, depth = np.empty((capacity, 3)), np.empty(capacity)
    count = 0
    near = np.empty(len(points), np.int64)
    rho = np.empty(len(points))  # distance of each point in the ball from the element's centre
    local = np.empty((len(points), 3))  # and its position in the element's link frame
    point = np.empty(capacity, np.int64)  # the object point of each row
    deepest = np.empty(keep)  # violations (floor - depth) of an element's deepest rows, descending
    central = np.empty(keep, np.int64)  # the points in the ball nearest to the centre
    for c in range(len(radii)):
        first_row = count
        deepest[:] = -np.inf
        R, o = R_links[c], origins[c]
        centre = np.empty(3)
        for i in range(3):
            centre[i] = (R[i, 0] * centres[c, 0] + R[i, 1] * centres[c, 1]
                         + R[i, 2] * centres[c, 2] + o[i])
        ball2 = (radii[c] + reach) ** 2
        box_lo, box_hi = boxes[c, 0], boxes[c, 1]
        hint = plane_start[c]
        n_ball = 0
        n_central = 0
        n_near = ball_box_candidates(centre, radii[c] + reach, R, o, box_lo, box_hi, cells, near)
        for k in near[:n_near]:
            d2 = 0.0
            for i in range(3):
                d2 += (points[k, i] - centre[i]) ** 2
            if d2 > ball2:
                continue
            outside = False
            for j in range(3):  # the point in the element's link frame
                x = ((points[k, 0] - o[0]) * R[0, j] + (points[k, 1] - o[1]) * R[1, j]
                     + (points[k, 2] - o[2]) * R[2, j])
                local[n_ball, j] = x
                outside = outside or x < box_lo[j] or x > box_hi[j]
            if outside:
                continue
            near[n_ball], rho[n_ball] = k, np.sqrt(d2)  # compact: n_ball never passes the scan
            slot = min(n_central, keep - 1)
            if n_central < keep or rho[n_ball] < rho[central[slot]]:
                while slot > 0 and rho[central[slot - 1]] > rho[n_ball]:
                    central[slot] = central[slot - 1]
                    slot -= 1
                central[slot] = n_ball
                n_central = min(n_central + 1, keep)
            n_ball += 1
        for t in range(n_central + n_ball):  # the central points, then the others
            m = central[t] if t < n_central else t - n_central
            if rho[m] == np.inf:  # a central point, done
                continue
            # a point rho from the centre is at most extent - rho deep: skip it when that
            # is shallower than `keep` rows already found
            shallow = floors[c] - min(rho[m] - extents[c], 0.0) < deepest[keep - 1]
            if t < n_central:
                rho[m] = np.inf
            if shallow:
                continue
            k = near[m]
            x = local[m]
            # the face that left the last point out often leaves this one out too
            sd = (planes[hint, 0] * x[0] + planes[hint, 1] * x[1]
                  + planes[hint, 2] * x[2] - planes[hint, 3])
            if sd >= floors[c] + reach or floors[c] - sd < deepest[keep - 1]:
                continue
            best, face = _deepest_face(x, planes, plane_start[c], plane_start[c + 1],
                                       floors[c] + reach, floors[c], deepest[keep - 1])
            if face < 0:
                hint = -1 - face
                continue
            violation = floors[c] - best
            slot = keep - 1
            while slot > 0 and deepest[slot - 1] < violation:
                deepest[slot] = deepest[slot - 1]
                slot -= 1
            deepest[slot] = violation
            if count == capacity:
                capacity *= 2
                element, foot = _grow(element, capacity), _grow(foot, capacity)
                normal, depth = _grow(normal, capacity), _grow(depth, capacity)
                point = _grow(point, capacity)
            element[count], depth[count], point[count] = c, best, k
            for i in range(3):
                foot[count, i] = x[i] - best * planes[face, i]
                normal[count, i] = -(R[i, 0] * planes[face, 0] + R[i, 1] * planes[face, 1]
                                     + R[i, 2] * planes[face, 2])
            count += 1
        kept = first_row  # drop the rows found before `keep` deeper ones
        for r in range(first_row, count):
            if floors[c] - depth[r] >= deepest[keep - 1]:
                element[kept], depth[kept], point[kept] = element[r], depth[r], point[r]
                copy_into(foot[kept], foot[r]), copy_into(normal[kept], normal[r])
                kept += 1
        count = kept
        # put the element's rows in point order
        by_point = np.argsort(point[first_row:count]) + first_row
        copy_into(foot[first_row:count], foot[by_point])
        copy_into(normal[first_row:count], normal[by_point])
        copy_into(depth[first_row:count], depth[by_point])
        copy_into(point[first_row:count], point[by_point])
    return (element[:count].copy(), foot[:count].copy(), normal[:count].copy(),
            depth[:count].copy(), point[:count].copy())


@kernel(inline=True)
def _deepest_face(local, planes, first, last, limit, floor, cut):
    """The face plane (rows ``first:last`` of ``planes``) a point ``local`` (3,) lies highest
    above and that height, ``(height, face)``; or, when the point is out by ``limit`` or more
    or ``floor - height`` falls below ``cut``, ``(height so far, -1 - the face showing it)``
    (it stops at that face)."""
    best, face = -np.inf, -1
    for f in range(first, last):
        sd = planes[f, 0] * local[0] + planes[f, 1] * local[1] + planes[f, 2] * local[2] \
            - planes[f, 3]
        if sd > best:
            best, face = sd, f
            if best >= limit or floor - best < cut:
                return best, -1 - f
    return best, face


@kernel(error_model="python")
def _grow(values, capacity):
    """``values`` copied into a longer array of ``capacity`` rows."""
    out = np.empty((capacity,) + values.shape[1:], values.dtype)
    copy_into(out[:len(values)], values)
    return out
