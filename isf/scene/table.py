"""The support plane of a scene (a table or a bin floor), given or found by RANSAC.

:func:`find_table` fits the dominant plane of the observed points: RANSAC (Fischler and Bolles
1981) over random triples of points, keeping the plane with the most points within
``threshold``, then a least-squares refit (the smallest principal direction of the inliers)
repeated on the refitted plane's inliers. The plane's normal is turned towards the cameras: the
free side of the table is the side they look from.
"""

from __future__ import annotations

import numpy as np

from ..collision.checker import Plane
from ..exceptions import InvalidInputError, ObjectLoadError

__all__ = ["TABLE_MARGIN", "find_table", "resolve_table"]

TABLE_MARGIN = 0.005
"""Points lower than this above the table plane are the table's, not an object's, metres."""

_RANSAC_ITERATIONS = 300
_RANSAC_POINTS = 20_000  # points RANSAC scores hypotheses on
_REFITS = 3


def find_table(points: np.ndarray, cameras: np.ndarray, *, threshold: float = 0.004,
               seed: int = 0, name: str = "table") -> Plane:
    """The dominant plane of ``points`` by RANSAC and a least-squares refit.

    Args:
        points: observed points (M, 3), scene frame, metres.
        cameras: camera positions (C, 3), scene frame; the plane's normal points to their side.
        threshold: distance within which a point supports a plane, metres (about three times
            the depth noise).
        seed: seed of the random triples (the same points give the same plane).
        name: the obstacle's name in collision reports.

    Raises:
        ObjectLoadError: fewer than 3 points, or no plane holds at least 10 % of them.
    """
    if len(points) < 3:
        raise ObjectLoadError("the scene has fewer than 3 points: no table can be found in it")
    rng = np.random.default_rng(seed)
    scored = points if len(points) <= _RANSAC_POINTS else \
        points[rng.choice(len(points), _RANSAC_POINTS, replace=False)]
    triples = scored[rng.integers(0, len(scored), size=(_RANSAC_ITERATIONS, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    good = length > 1e-12
    normals = normals[good] / length[good, None]
    offsets = np.einsum("ij,ij->i", normals, triples[good, 0])
    support = np.zeros(len(normals), dtype=np.int64)
    for start in range(0, len(normals), 32):  # (32, M) distance blocks
        block = np.abs(scored @ normals[start:start + 32].T - offsets[start:start + 32])
        support[start:start + 32] = (block < threshold).sum(axis=0)
    if len(support) == 0 or support.max() < 0.1 * len(scored):
        raise ObjectLoadError("no plane holds 10 % of the scene's points: the table cannot be found; "
                              "pass its height (--table Z) or none")
    best = int(np.argmax(support))
    normal, offset = normals[best], offsets[best]
    for _ in range(_REFITS):
        inliers = points[np.abs(points @ normal - offset) < threshold]
        centre = inliers.mean(axis=0)
        normal = np.linalg.svd(inliers - centre, full_matrices=False)[2][-1]
        offset = float(normal @ centre)
    if np.mean(cameras @ normal - offset) < 0:
        normal, offset = -normal, -offset
    return Plane(normal, offset, name)


def resolve_table(table, points: np.ndarray, cameras: np.ndarray) -> Plane | None:
    """The ``table`` argument of :func:`isf.load_scene` as a plane: None (no table), a height
    ``z`` of the scene frame (the plane ``z = const``, free above: the scene's z axis points up),
    a :class:`~isf.collision.checker.Plane`, or ``"auto"`` (:func:`find_table`).

    Raises:
        InvalidInputError: any other value, or a height that is not finite.
        ObjectLoadError: ``"auto"`` found no plane.
    """
    if table is None or isinstance(table, Plane):
        return table
    if isinstance(table, str):
        if table == "auto":
            return find_table(points, cameras)
        try:
            table = float(table)
        except ValueError:
            raise InvalidInputError(f"table {table!r} must be 'auto', a height in metres or a "
                                    "Plane") from None
    if isinstance(table, bool) or not isinstance(table, (int, float, np.integer, np.floating)) \
            or not np.isfinite(table):
        raise InvalidInputError(f"table must be 'auto', a finite height in metres or a Plane, got "
                                f"{table!r}")
    return Plane.table(float(table))
