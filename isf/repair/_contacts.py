"""The collision repair's contact pairs, compiled (``pull`` mode of :mod:`isf.repair.clearance`).

Each repair step matches every contact surface of the gripper to the object afresh, as
:func:`isf.fitting.correspondence.match_many` does with one group per surface: each contact point's
nearest object point, then the normal, outlier and duplicate filters per surface.
:func:`contact_pairs` does it in one call from the contact links' poses; each point's search
starts from its previous answer (exact either way, it only bounds the search).
"""

from __future__ import annotations

import numpy as np

from ..compiled.kernels import kernel
from ..fitting.correspondence import filter_pairs
from ..fitting.engine_kernel import row_dot
from ..fitting.moment_kernels import link_poses, place
from ..search.nearest import nearest_point, search_scratch

__all__ = ["contact_pairs"]


@kernel
def contact_pairs(T, R, p, contact, surface_starts, obj, guess, outlier_factor, outlier_floor,
                  cos_limit):
    """The contact points at a state, and those that match the object.

    Args:
        T, R, p: the palm pose (4, 4) and the contact links' poses (L, 3, 3), (L, 3), gripper
            frame.
        contact: every contact point's link (P,), and its position and normal in its link's
            frame (P, 3), grouped by contact surface.
        surface_starts: the first point of each surface, (S,).
        obj: the object's points and normals (N, 3) and :attr:`isf.search.nearest.NearestPoints.tree`.
        guess: each point's object point of the previous call, or -1 (P,) (updated).
        outlier_factor, outlier_floor: a pair is an outlier when farther than both this times
            its surface's median distance and ``outlier_floor`` (metres).
        cos_limit: a pair is kept only when the dot product of its normals is at most this
            (``-cos(max_normal_angle)``; ``inf`` keeps every pair).

    Returns:
        (indices (K,) of the kept contact points, every contact point in the object frame
        (P, 3), the object point of every contact point (P,)): the pairs of
        :func:`isf.fitting.correspondence.match_many` with the surfaces as groups and duplicates
        rejected per surface.
    """
    point_link, points_link, normals_link = contact
    obj_points, obj_normals, tree = obj
    A, a = np.empty((len(R), 3, 3)), np.empty((len(R), 3))
    link_poses(T, R, p, A, a)
    n = len(point_link)
    points, normals = np.empty((n, 3)), np.empty((n, 3))
    dist, target = np.empty(n), np.empty(n, np.int64)
    compatible = np.empty(n, np.bool_)
    scratch = search_scratch()
    for i in range(n):
        place(A, a, point_link[i], points_link, normals_link, i, points, normals, i)
        t, d2 = nearest_point(points[i, 0], points[i, 1], points[i, 2], guess[i], obj_points,
                              tree, scratch, np.inf)
        guess[i], target[i], dist[i] = t, t, np.sqrt(d2)
        compatible[i] = row_dot(normals, i, obj_normals, t) <= cos_limit
    # a typed True, not a literal: the filter_pairs that match_many compiles serves here too
    keep = filter_pairs(dist, target, surface_starts, surface_starts, outlier_factor,
                         outlier_floor, compatible, np.bool_(True))
    return np.flatnonzero(keep), points, target
