"""A fixed point set binned in a uniform grid, to find the points near a ball quickly.

:func:`ball_box_candidates` lists the points of the grid cells within a cell's width of a
ball (the extra width so that rounding never hides a point near a cell's faces) that may hold
points of a box given in another frame: a superset of the points in both, without testing
every point.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel

__all__ = ["GridCells", "PointGrid", "ball_box_candidates"]

MAX_CELLS = 1 << 18
"""The cell grows beyond the asked size to keep the grid at most this many cells."""


class GridCells(NamedTuple):
    """The cells of a :class:`PointGrid` of N points, C cells."""

    order: np.ndarray
    """Point indices sorted by cell, (N,) int64."""
    start: np.ndarray
    """The first entry of each cell in ``order``, (C + 1,) int64."""
    lo: np.ndarray
    """The grid's corner, (3,) float64, m."""
    cell: float
    """Cell width, m."""
    shape: np.ndarray
    """Cells per axis, (3,) int64."""


class PointGrid:
    """Points (N, 3) in a grid of cubic cells about ``cell`` metres wide (larger when the points
    spread so far that the grid would exceed ``MAX_CELLS`` cells).

    Attributes:
        points: the points, (N, 3).
        arrays: the :class:`GridCells`, for :func:`ball_box_candidates`.
    """

    def __init__(self, points: np.ndarray, cell: float):
        self.points = np.ascontiguousarray(points, dtype=float)
        lo = self.points.min(axis=0) if len(self.points) else np.zeros(3)
        extent = self.points.max(axis=0) - lo if len(self.points) else np.zeros(3)
        cell = max(float(cell), float(np.prod(extent + cell) / MAX_CELLS) ** (1.0 / 3.0), 1e-9)
        shape = (np.floor(extent / cell) + 1).astype(np.int64)
        keys = _cell_keys(self.points, lo, cell, shape)
        order = np.argsort(keys, kind="stable")
        start = np.searchsorted(keys[order], np.arange(int(np.prod(shape)) + 1))
        self.arrays = GridCells(order.astype(np.int64), start.astype(np.int64), lo, cell, shape)


@kernel
def _cell_index(x, lo, cell, size):
    """Cell of coordinate ``x`` along one axis, clipped to ``[0, size)``."""
    return min(max(int(np.floor((x - lo) / cell)), 0), size - 1)


@kernel
def _cell_keys(points, lo, cell, shape):
    """Flat cell index of every point (N,)."""
    keys = np.empty(len(points), np.int64)
    for k in range(len(points)):
        key = 0
        for d in range(3):
            key = key * shape[d] + _cell_index(points[k, d], lo[d], cell, shape[d])
        keys[k] = key
    return keys


@kernel
def ball_box_candidates(centre, radius, R, origin, box_lo, box_hi, cells, out):
    """Indices of the points in the cells within a cell's width of the ball (``centre`` (3,),
    ``radius`` m) whose centre lies in the box ``[box_lo, box_hi]`` ((3,) each, metres, infinite
    for none) of the frame of pose ``R`` (3, 3), ``origin`` (3,) (a point ``x`` is at
    ``R^T (x - origin)`` in it) grown by 0.87 cell widths on every side (a point of a cell is at
    most half its diagonal, 0.866 widths, from its centre), so every point of the ball in the
    box is listed; written to the front of ``out`` (N,) cell by cell; returns how many.
    ``cells``: the grid's :class:`GridCells`."""
    order, start, lo, cell, shape = cells.order, cells.start, cells.lo, cells.cell, cells.shape
    first, last = np.empty(3, np.int64), np.empty(3, np.int64)
    for d in range(3):
        if centre[d] + radius < lo[d] - cell or centre[d] - radius > lo[d] + shape[d] * cell + cell:
            return 0
        first[d] = _cell_index(centre[d] - radius, lo[d], cell, shape[d]) - 1
        last[d] = _cell_index(centre[d] + radius, lo[d], cell, shape[d]) + 1
        first[d], last[d] = max(first[d], 0), min(last[d], shape[d] - 1)
    n = 0
    reach2 = (radius + cell) ** 2  # cells within a cell's width of the ball
    grow = 0.87 * cell
    u = np.empty(3)
    for i in range(first[0], last[0] + 1):
        gi = _gap(centre[0], lo[0] + i * cell, cell) ** 2
        for j in range(first[1], last[1] + 1):
            gij = gi + _gap(centre[1], lo[1] + j * cell, cell) ** 2
            if gij > reach2:
                continue
            row = (i * shape[1] + j) * shape[2]
            for k in range(first[2], last[2] + 1):
                if gij + _gap(centre[2], lo[2] + k * cell, cell) ** 2 > reach2:
                    continue
                u[0] = lo[0] + (i + 0.5) * cell - origin[0]
                u[1] = lo[1] + (j + 0.5) * cell - origin[1]
                u[2] = lo[2] + (k + 0.5) * cell - origin[2]
                outside = False
                for a in range(3):
                    x = R[0, a] * u[0] + R[1, a] * u[1] + R[2, a] * u[2]
                    outside = outside or x < box_lo[a] - grow or x > box_hi[a] + grow
                if outside:
                    continue
                for m in range(start[row + k], start[row + k + 1]):
                    out[n] = order[m]
                    n += 1
    return n


@kernel(inline=True)
def _gap(x, low, cell):
    """Distance from ``x`` to the interval ``[low, low + cell]`` along one axis."""
    return max(low - x, x - low - cell, 0.0)
