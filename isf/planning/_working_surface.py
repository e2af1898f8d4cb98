"""The surface the planner matches against: the object at no finer a spacing than the gripper needs.

ISF matches a contact point to its nearest object point and fits point-to-plane (eq. 7), so
surface samples much closer together than the gripper's own contact points add
nearest-neighbour work but no information: the fitted distance to a locally smooth surface
does not depend on where on the tangent plane the matched point lies. :func:`working_surface`
therefore thins an object whose spacing is finer than :data:`SPACING_FACTOR` times the
gripper's contact-point spacing to that spacing (one point per voxel, the sample nearest the
voxel's mean, with its own normal); coarser objects are used as they are. This keeps the cost
of :func:`isf.plan` independent of how densely a mesh was sampled or a cloud was captured.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from ..exceptions import InvalidInputError
from ..gripper.model import Gripper
from ..object.mesh_sampling import voxel_representatives
from ..object.surface import ObjectSurface
from ..search.voxel_grid import voxel_labels

__all__ = ["SPACING_FACTOR", "contact_spacing", "resolve_spacing", "working_spacing",
           "working_surface"]

logger = logging.getLogger(__name__)

SPACING_FACTOR = 2.0
"""The working spacing is this multiple of the gripper's contact-point spacing."""


def contact_spacing(gripper: Gripper) -> float:
    """Median distance from a contact point to its nearest neighbour on the same contact
    surface (the finest pyramid level), metres."""
    gaps = []
    for k in range(len(gripper.surfaces)):
        points = gripper.points_link[gripper.point_surface == k]
        if len(points) > 1:
            gaps.append(cKDTree(points).query(points, k=2)[0][:, 1])
    return float(np.median(np.concatenate(gaps))) if gaps else 0.0


def working_spacing(gripper: Gripper) -> float:
    """The finest object spacing worth matching against with ``gripper``, metres."""
    return SPACING_FACTOR * contact_spacing(gripper)


def resolve_spacing(value: float | str | None, gripper: Gripper) -> float:
    """The ``working_spacing`` argument of :func:`isf.plan` in metres: ``"auto"`` gives
    :func:`working_spacing`, None gives 0 (keep the object), a number > 0 itself.

    Raises:
        InvalidInputError: any other value.
    """
    if value is None:
        return 0.0
    if isinstance(value, str) and value == "auto":
        return working_spacing(gripper)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(value) and value > 0):
        raise InvalidInputError(f"working_spacing must be 'auto', None or a spacing > 0 in metres, "
                                f"got {value!r}")
    return float(value)


def working_surface(obj: ObjectSurface, spacing: float) -> ObjectSurface:
    """``obj`` thinned to about ``spacing`` metres between points (voxels of that edge), or
    ``obj`` itself when its own spacing is at least that (or ``spacing`` is 0).

    The result keeps the object's name and mesh; its points are a subset of ``obj.points``. It
    is kept with ``obj``, so planning on the same object again reuses it and its search.
    """
    if not spacing > 0.0 or obj.spacing >= spacing:
        return obj
    if spacing not in obj._thinned:
        obj._thinned[spacing] = _thinned(obj, spacing)
    return obj._thinned[spacing]


def _thinned(obj: ObjectSurface, spacing: float) -> ObjectSurface:
    """:func:`working_surface`, computed."""
    labels, n_voxels = voxel_labels(obj.points, spacing)
    if n_voxels >= obj.n_points:
        return obj
    pick = voxel_representatives(obj.points, labels, n_voxels)
    logger.info("%s: matching against %d of its %d points (spacing %.3g m, the gripper's "
                "contact points are %.3g m apart)", obj.name, len(pick), obj.n_points, spacing,
                spacing / SPACING_FACTOR)
    return ObjectSurface(points=obj.points[pick], normals=obj.normals[pick], spacing=float(spacing),
                         name=obj.name, mesh_vertices=obj.mesh_vertices, mesh_faces=obj.mesh_faces,
                         viewpoints=obj.viewpoints)
