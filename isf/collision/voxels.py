"""A voxel grid around a closed mesh object: space certainly outside it, and how far from it.

It settles collision tests early. The grid covers the mesh's bounding box with voxels to
spare on every side. A voxel that a triangle's bounding box overlaps is *blocked*:

* the other voxels that a face-adjacent path of unblocked voxels joins to the grid's border
  are *outside*: the path never meets the surface, so the whole voxel lies outside the
  (closed) mesh, and so does all space beyond the grid. An axis-aligned box query asks
  whether every voxel it overlaps is outside (a summed-volume table of the blocked and
  enclosed voxels answers it in eight look-ups);
* the surface lies in the blocked voxels, so a point is at least as far from it as its voxel's
  box is from the nearest blocked voxel's box: ``sqrt(sum_i max(|d_i| - 1, 0)^2)`` voxel edges
  for index offsets ``d``, the exact Euclidean distance transform of the blocked voxels grown
  by one voxel on every side; a point ``p`` beyond the grid, with ``g`` its nearest point on
  the grid, is at least ``sqrt(|p - g|^2 + b(g)^2)`` away, where ``b(g)`` bounds ``g``'s
  distance (the angle at ``g`` towards any point of the box is obtuse).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel

__all__ = ["SurfaceVoxels", "VoxelArrays", "kernel_arrays"]

MIN_VOXEL = 0.001  # m
MAX_VOXELS = 1 << 17  # the voxel grows beyond MIN_VOXEL to keep the grid this small


@kernel(error_model="python")
def _blocked(vertices, faces, lo, size, shape):
    """Voxels (shape) overlapped by the bounding box of some triangle (vertices (V, 3), faces
    (F, 3)); a box touching a voxel's face counts as overlapping it."""
    blocked = np.zeros((shape[0], shape[1], shape[2]), np.bool_)
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for f in range(len(faces)):
        for d in range(3):
            a = min(vertices[faces[f, 0], d], vertices[faces[f, 1], d], vertices[faces[f, 2], d])
            b = max(vertices[faces[f, 0], d], vertices[faces[f, 1], d], vertices[faces[f, 2], d])
            first[d] = max(int(np.floor((a - lo[d]) / size - 1e-9)), 0)
            last[d] = min(int(np.floor((b - lo[d]) / size + 1e-9)), shape[d] - 1)
        for i in range(first[0], last[0] + 1):
            for j in range(first[1], last[1] + 1):
                for k in range(first[2], last[2] + 1):
                    blocked[i, j, k] = True
    return blocked


@kernel(error_model="python")
def _not_outside(blocked):
    """Voxels that no face-adjacent path of unblocked voxels joins to the grid's border."""
    nx, ny, nz = blocked.shape
    reached = np.zeros(blocked.shape, np.bool_)
    queue = np.empty((nx * ny * nz, 3), np.int64)
    end = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                border = i == 0 or j == 0 or k == 0 or i == nx - 1 or j == ny - 1 or k == nz - 1
                if border and not blocked[i, j, k]:
                    reached[i, j, k] = True
                    queue[end, 0], queue[end, 1], queue[end, 2] = i, j, k
                    end += 1
    head = 0
    while head < end:
        i, j, k = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        for step in range(6):
            a, b, c = i, j, k
            if step == 0:
                a -= 1
            elif step == 1:
                a += 1
            elif step == 2:
                b -= 1
            elif step == 3:
                b += 1
            elif step == 4:
                c -= 1
            else:
                c += 1
            if 0 <= a < nx and 0 <= b < ny and 0 <= c < nz and not blocked[a, b, c] \
                    and not reached[a, b, c]:
                reached[a, b, c] = True
                queue[end, 0], queue[end, 1], queue[end, 2] = a, b, c
                end += 1
    return ~reached


@kernel
def _transform_line(f, out, site, bound):
    """``out[q] = min_p (q - p)^2 + f[p]`` over a line ``f`` (n,) of squared distances (``inf``
    where none): the lower envelope of parabolas (Felzenszwalb and Huttenlocher, 2012).
    ``site`` (n,) and ``bound`` (n + 1,): scratch."""
    n = len(f)
    k = -1
    for q in range(n):
        if f[q] == np.inf:
            continue
        while k >= 0:  # drop the parabolas the new one lies below from where they start
            p = site[k]
            s = ((f[q] + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
            if s > bound[k]:
                break
            k -= 1
        k += 1
        site[k] = q
        if k == 0:
            bound[0] = -np.inf
        else:
            p = site[k - 1]
            bound[k] = ((f[q] + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
        bound[k + 1] = np.inf
    if k < 0:
        out[:] = np.inf
        return
    j = 0
    for q in range(n):
        while bound[j + 1] < q:
            j += 1
        out[q] = (q - site[j]) ** 2 + f[site[j]]


@kernel
def _gaps(blocked):
    """Squared distance, in voxel edges squared, from every voxel's box to the nearest blocked
    voxel's box, ``min_b sum_i max(|v_i - b_i| - 1, 0)^2`` (float64, exact integers); the grid's
    squared diagonal when none is blocked.

    Per axis, ``max(|d| - 1, 0)^2 = min_{e in {-1, 0, 1}} (d - e)^2``, so this is the squared
    Euclidean distance transform of the blocked voxels grown by one voxel on every side (the
    nearest grown voxel towards a voxel of the grid lies in the grid), taken axis by axis.
    """
    nx, ny, nz = blocked.shape
    gaps = np.full(blocked.shape, np.inf)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if blocked[i, j, k]:
                    for a in range(max(i - 1, 0), min(i + 2, nx)):
                        for b in range(max(j - 1, 0), min(j + 2, ny)):
                            for c in range(max(k - 1, 0), min(k + 2, nz)):
                                gaps[a, b, c] = 0.0
    n = max(nx, ny, nz)
    line, out = np.empty(n), np.empty(n)
    site, bound = np.empty(n, np.int64), np.empty(n + 1)
    for axis in (2, 1, 0):  # along z, then y, then x
        _transform_axis(gaps, axis, line, out, site, bound)
    diagonal = float(nx * nx + ny * ny + nz * nz)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                gaps[i, j, k] = min(gaps[i, j, k], diagonal)
    return gaps


@kernel
def _transform_axis(gaps, axis, line, out, site, bound):
    """:func:`_transform_line` on every line of ``gaps`` (3-D) along ``axis``, in place
    (``line``, ``out``: scratch of the longest side; ``site``, ``bound``: its scratch)."""
    m = gaps.shape[axis]
    u, v = (axis + 1) % 3, (axis + 2) % 3
    at = np.zeros(3, np.int64)
    for a in range(gaps.shape[u]):
        for b in range(gaps.shape[v]):
            at[u], at[v] = a, b
            for c in range(m):
                at[axis] = c
                line[c] = gaps[at[0], at[1], at[2]]
            _transform_line(line[:m], out[:m], site, bound)
            for c in range(m):
                at[axis] = c
                gaps[at[0], at[1], at[2]] = out[c]


@kernel(inline=True)
def _cell(p, lo, size, n):
    """The voxel (of ``n``) nearest coordinate ``p`` and the squared distance to the grid's span."""
    g = min(max(p, lo), lo + n * size)
    return min(max(int(np.floor((g - lo) / size)), 0), n - 1), (p - g) ** 2


@kernel(inline=True)
def distance_below(gaps, lo, size, x, y, z):
    """A lower bound of the distance of point ``(x, y, z)`` to the blocked voxels (``gaps`` of
    :func:`_gaps`, grid corner ``lo``, voxel edge ``size``), metres."""
    a, da = _cell(x, lo[0], size, gaps.shape[0])
    b, db = _cell(y, lo[1], size, gaps.shape[1])
    c, dc = _cell(z, lo[2], size, gaps.shape[2])
    return np.sqrt(da + db + dc + gaps[a, b, c] * (size * size))


@kernel
def points_distance_below(gaps, lo, size, points):
    """:func:`distance_below` of points (M, 3), metres (M,)."""
    out = np.empty(len(points))
    for q in range(len(points)):
        out[q] = distance_below(gaps, lo, size, points[q, 0], points[q, 1], points[q, 2])
    return out


@kernel(inline=True)
def _span(a, b, lo, size, n):
    """The voxels ``[first, last)`` (of ``n``) that the interval ``[a, b]`` overlaps."""
    return max(int(np.floor((a - lo) / size)), 0), min(int(np.floor((b - lo) / size)), n - 1) + 1


@kernel(inline=True)
def box_clear(table, lo, size, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z):
    """Does the box ``[lo_*, hi_*]`` overlap no voxel counted in the summed-volume ``table``
    (grid corner ``lo``, voxel edge ``size``)?"""
    a0, a1 = _span(lo_x, hi_x, lo[0], size, table.shape[0] - 1)
    b0, b1 = _span(lo_y, hi_y, lo[1], size, table.shape[1] - 1)
    c0, c1 = _span(lo_z, hi_z, lo[2], size, table.shape[2] - 1)
    if a0 >= a1 or b0 >= b1 or c0 >= c1:
        return True
    count = (table[a1, b1, c1] - table[a0, b1, c1] - table[a1, b0, c1] - table[a1, b1, c0]
             + table[a0, b0, c1] + table[a0, b1, c0] + table[a1, b0, c0] - table[a0, b0, c0])
    return count == 0


@kernel
def boxes_clear(table, lo, size, box_lo, box_hi):
    """:func:`box_clear` of boxes (M, 3 corners), (M,) bool."""
    out = np.empty(len(box_lo), np.bool_)
    for q in range(len(box_lo)):
        out[q] = box_clear(table, lo, size, box_lo[q, 0], box_lo[q, 1], box_lo[q, 2],
                           box_hi[q, 0], box_hi[q, 1], box_hi[q, 2])
    return out


class SurfaceVoxels:
    """The voxels around a closed mesh (see the module docs).

    Args:
        vertices: mesh vertices (V, 3), metres; faces: triangles (F, 3). The mesh must be
            closed (watertight): on an open mesh the "outside" would leak inside.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        self.size = max(MIN_VOXEL, float(np.prod(hi - lo + 2 * MIN_VOXEL) / MAX_VOXELS) ** (1 / 3))
        """Voxel edge, metres."""
        self.lo = lo - 2 * self.size  # two spare voxels below, at least two above
        shape = np.floor((hi - self.lo) / self.size).astype(np.int64) + 3
        blocked = _blocked(vertices, faces, self.lo, self.size, shape)
        counted = _not_outside(blocked)
        self.gaps = _gaps(blocked)
        """Squared distance from every voxel's box to the nearest blocked voxel's box, in voxel
        edges squared (float64, exact integers)."""
        self.table = np.zeros(shape + 1, dtype=np.int64)
        """Summed-volume table of the voxels not outside, (shape + 1) (int64)."""
        self.table[1:, 1:, 1:] = counted.cumsum(0).cumsum(1).cumsum(2)

    def clear(self, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        """Whether each axis-aligned box (corners (M, 3), metres) lies wholly outside the mesh,
        by its voxels, (M,) bool. False says nothing."""
        box_lo = np.ascontiguousarray(box_lo, dtype=np.float64)
        box_hi = np.ascontiguousarray(box_hi, dtype=np.float64)
        return boxes_clear(self.table, self.lo, self.size, box_lo, box_hi)

    def distance_below(self, points: np.ndarray) -> np.ndarray:
        """A lower bound of each point's (M, 3) distance to the mesh, metres (M,)."""
        return points_distance_below(self.gaps, self.lo, self.size,
                               np.ascontiguousarray(points, dtype=np.float64))


class VoxelArrays(NamedTuple):
    """The arrays of :class:`SurfaceVoxels` for compiled callers (:func:`kernel_arrays`)."""

    present: bool
    """Whether the object has voxels (else the arrays are placeholders)."""
    table: np.ndarray
    """:attr:`SurfaceVoxels.table`, (A, B, C) int64."""
    gaps: np.ndarray
    """:attr:`SurfaceVoxels.gaps`, (A, B, C) float64, m."""
    lo: np.ndarray
    """:attr:`SurfaceVoxels.lo`, (3,) float64, m."""
    size: float
    """:attr:`SurfaceVoxels.size`, m."""


def kernel_arrays(voxels: SurfaceVoxels | None) -> VoxelArrays:
    """The :class:`VoxelArrays` of ``voxels``; for None, ``present`` is False and the arrays are
    placeholders of the same types (so the kernels compile once)."""
    if voxels is None:
        return VoxelArrays(False, np.zeros((1, 1, 1), np.int64), np.zeros((1, 1, 1)), np.zeros(3),
                           1.0)
    return VoxelArrays(True, voxels.table, voxels.gaps, voxels.lo, voxels.size)
