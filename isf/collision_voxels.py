"""A voxel grid around a closed mesh object: space certainly outside it, and how far from it.

It settles collision tests early. The grid covers the mesh's bounding box with voxels to
spare on every side. A voxel that a triangle's bounding box overlaps is *blocked*:

* the other voxels that a face-adjacent path of unblocked voxels joins to the grid's border
  are *outside*: the path never meets the surface, so the whole voxel lies outside the
  (closed) mesh, and so does all space beyond the grid. An axis-aligned box query asks
  whether every voxel it overlaps is outside (a summed-volume table of the blocked and
  enclosed voxels answers it in eight look-ups);
* a voxel ``c`` steps (Chebyshev, in voxels) from the nearest blocked one is at least
  ``(c - 1)`` voxel edges from the surface; a point ``p`` beyond the grid, with ``g`` its
  nearest point on the grid, at least ``sqrt(|p - g|^2 + b(g)^2)`` where ``b(g)`` bounds
  ``g``'s distance (the angle at ``g`` towards any point of the box is obtuse).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["SurfaceVoxels"]

MIN_VOXEL = 0.001  # m
MAX_VOXELS = 1 << 17  # the voxel grows beyond MIN_VOXEL to keep the grid this small


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def _steps(blocked):
    """Chebyshev distance of every voxel to the nearest blocked one, in voxels (int32); the
    grid's size in voxels when none is blocked."""
    nx, ny, nz = blocked.shape
    steps = np.full(blocked.shape, nx + ny + nz, np.int32)
    queue = np.empty((nx * ny * nz, 3), np.int64)
    end = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if blocked[i, j, k]:
                    steps[i, j, k] = 0
                    queue[end, 0], queue[end, 1], queue[end, 2] = i, j, k
                    end += 1
    head = 0
    while head < end:  # breadth first over the 26 neighbours: Chebyshev steps
        i, j, k = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        for a in range(max(i - 1, 0), min(i + 2, nx)):
            for b in range(max(j - 1, 0), min(j + 2, ny)):
                for c in range(max(k - 1, 0), min(k + 2, nz)):
                    if steps[a, b, c] > steps[i, j, k] + 1:
                        steps[a, b, c] = steps[i, j, k] + 1
                        queue[end, 0], queue[end, 1], queue[end, 2] = a, b, c
                        end += 1
    return steps


@njit(cache=True, error_model="numpy")
def _distance_below(steps, lo, size, points):
    """Lower bounds of the distance of points (M, 3) to the blocked voxels, metres (M,)."""
    out = np.empty(len(points))
    cell = np.empty(3, np.int64)
    for q in range(len(points)):
        beyond = 0.0  # squared distance to the grid
        for d in range(3):
            x = min(max(points[q, d], lo[d]), lo[d] + steps.shape[d] * size)
            beyond += (points[q, d] - x) ** 2
            cell[d] = min(max(int(np.floor((x - lo[d]) / size)), 0), steps.shape[d] - 1)
        inner = max(steps[cell[0], cell[1], cell[2]] - 1, 0) * size
        out[q] = np.sqrt(beyond + inner * inner)
    return out


@njit(cache=True, error_model="numpy")
def _clear(table, lo, size, box_lo, box_hi):
    """Per box (M, 3 corners): does it overlap no voxel counted in the summed-volume ``table``?"""
    m = len(box_lo)
    out = np.empty(m, np.bool_)
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for q in range(m):
        empty = False
        for d in range(3):
            n = table.shape[d] - 1
            first[d] = max(int(np.floor((box_lo[q, d] - lo[d]) / size)), 0)
            last[d] = min(int(np.floor((box_hi[q, d] - lo[d]) / size)), n - 1) + 1
            if first[d] >= last[d]:
                empty = True
        if empty:
            out[q] = True
            continue
        a0, b0, c0 = first[0], first[1], first[2]
        a1, b1, c1 = last[0], last[1], last[2]
        count = (table[a1, b1, c1] - table[a0, b1, c1] - table[a1, b0, c1] - table[a1, b1, c0]
                 + table[a0, b0, c1] + table[a0, b1, c0] + table[a1, b0, c0] - table[a0, b0, c0])
        out[q] = count == 0
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
        self._steps = _steps(blocked)
        self._table = np.zeros(shape + 1, dtype=np.int64)
        self._table[1:, 1:, 1:] = counted.cumsum(0).cumsum(1).cumsum(2)

    def clear(self, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        """Whether each axis-aligned box (corners (M, 3), metres) lies wholly outside the mesh,
        by its voxels, (M,) bool. False says nothing."""
        box_lo = np.ascontiguousarray(box_lo, dtype=np.float64)
        box_hi = np.ascontiguousarray(box_hi, dtype=np.float64)
        return _clear(self._table, self.lo, self.size, box_lo, box_hi)

    def distance_below(self, points: np.ndarray) -> np.ndarray:
        """A lower bound of each point's (M, 3) distance to the mesh, metres (M,)."""
        return _distance_below(self._steps, self.lo, self.size,
                               np.ascontiguousarray(points, dtype=np.float64))
