"""What the collision repair (:mod:`isf.repair.clearance`) keeps apart, prepared once and cached.

* :func:`gripper_side`: points sampled on every geometry element of the gripper (in its link
  frame), the elements' bounding spheres and floors, and the closed convex elements
  (``isf.collision.convex_elements.ConvexElements``). Cached per gripper and parameters, so the
  repairs of every plan with one gripper share them.
* :func:`object_side`: the object's tangent planes (``isf.collision.surface_distance.TangentPlanes``)
  on its points plus, for a closed mesh, area-uniform samples of the mesh; and a
  :class:`isf.search.point_grid.PointGrid` of the same points. Cached on the mesh
  (``isf.collision.surface_distance.mesh_memo``).

Both draw their random samples from one generator (seeded 0 by the repair): the object's
resampling takes its seed first, when there is one.
"""

from __future__ import annotations

import hashlib
import weakref
from typing import NamedTuple

import numpy as np
import trimesh

from ..collision.convex_elements import ConvexElements
from ..collision.surface_distance import TangentPlanes, closed_mesh, mesh_memo
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface
from ..search.point_grid import PointGrid

__all__ = ["GripperSide", "ObjectSide", "gripper_side", "object_side"]

MAX_OBJECT_SAMPLES = 40000  # dense resampling of a mesh object
GRID_CELL = 0.004  # cells of the grid that finds the object points near a convex element, m

_GRIPPER_MEMOS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class GripperSide(NamedTuple):
    """The gripper's geometry for the repair (arrays shared through the cache: read only).

    Attributes:
        frames: Pinocchio frame ids of the links with geometry, (L,).
        points_link: surface samples of every element, in their links' frames, (N, 3).
        element, owner, floor: each sample's element (N,), link (index into ``frames``) (N,)
            and floor (N,), metres: ``-contact_allowance`` on links with a contact surface,
            ``margin`` on the others.
        sphere_owner, sphere_centre, sphere_radius: per element its link (E,), bounding-sphere
            centre in the link frame (E, 3) and radius (E,), metres.
        convex: the closed convex elements.
    """

    frames: np.ndarray
    points_link: np.ndarray
    element: np.ndarray
    owner: np.ndarray
    floor: np.ndarray
    sphere_owner: np.ndarray
    sphere_centre: np.ndarray
    sphere_radius: np.ndarray
    convex: ConvexElements


class ObjectSide(NamedTuple):
    """The object's surface for the repair.

    Attributes:
        planes: tangent planes of the object's points and, when ``resampled``, of the dense
            samples of its closed mesh (after the object's points).
        grid: the same points, binned.
        resampled: whether the mesh was resampled (else the points are the object's own).
    """

    planes: TangentPlanes
    grid: PointGrid
    resampled: bool


def gripper_side(gripper: Gripper, spacing: float, max_samples: int, margin: float,
                 contact_allowance: float, rng: np.random.Generator) -> GripperSide:
    """The gripper's :class:`GripperSide`: samples about ``spacing`` metres apart (at most
    ``max_samples`` per element, box corners on top) drawn from ``rng`` (cached per gripper,
    parameters and the state of ``rng``)."""
    memo = _GRIPPER_MEMOS.setdefault(gripper, {})
    key = (spacing, max_samples, margin, contact_allowance, repr(rng.bit_generator.state))
    if key not in memo:
        memo[key] = _gripper_side(gripper, spacing, max_samples, margin, contact_allowance, rng)
    return memo[key]


def _gripper_side(gripper, spacing, max_samples, margin, contact_allowance, rng) -> GripperSide:
    model = gripper.model
    links = list(dict.fromkeys(g.link for g in gripper.geometries))
    link_of = np.array([links.index(g.link) for g in gripper.geometries], dtype=int)
    contact_links = set(gripper.contact_links)
    floor = np.array([-contact_allowance if link in contact_links else margin for link in links])
    samples = [_surface_samples(g.vertices, g.faces, spacing, max_samples, rng)
               for g in gripper.geometries]
    element = np.repeat(np.arange(len(samples)), [len(s) for s in samples])
    vertices = [np.asarray(g.vertices, float) for g in gripper.geometries]
    centre = np.array([v.mean(axis=0) for v in vertices])
    radius = np.array([np.linalg.norm(v - c, axis=1).max() for v, c in zip(vertices, centre)])
    convex = ConvexElements([(g.vertices, g.faces) for g in gripper.geometries], link_of,
                            floor[link_of])
    frames = np.array([model.getFrameId(link) for link in links], dtype=int)
    return GripperSide(frames, np.concatenate(samples), element, link_of[element],
                       floor[link_of[element]], link_of, centre, radius, convex)


def object_side(obj: ObjectSurface, spacing: float, rng: np.random.Generator) -> ObjectSide:
    """The object's :class:`ObjectSide`: a closed, outward mesh object finer than ``spacing``
    metres is resampled that densely (its own points are kept too), with a seed drawn from
    ``rng``, and the dense planes' Delaunay graph is deferred until the repair's searches have
    paid for it (:data:`isf.collision.surface_distance.GRAPH_PAYBACK`); a point cloud or an open mesh
    keeps its own points."""
    mesh = None if spacing >= obj.spacing else closed_mesh(obj)
    if mesh is None:  # the object's own points, and its search (with their graph)
        planes = TangentPlanes(obj.points, obj.normals, obj.spacing, search=obj.search)
        return ObjectSide(planes, PointGrid(planes.points, GRID_CELL), False)
    seed = int(rng.integers(2**31))
    digest = hashlib.blake2b(np.ascontiguousarray(obj.points).tobytes()
                             + np.ascontiguousarray(obj.normals).tobytes()).hexdigest()
    memo = mesh_memo(obj)
    key = ("repair surface", spacing, seed, digest)
    if key not in memo:
        count = int(np.clip(mesh.area / spacing**2, 1, MAX_OBJECT_SAMPLES))
        points, face = trimesh.sample.sample_surface(mesh, count, seed=seed)
        planes = TangentPlanes(np.concatenate([obj.points, points]),
                               np.concatenate([obj.normals, mesh.face_normals[face]]), spacing,
                               graph="deferred")
        memo[key] = ObjectSide(planes, PointGrid(planes.points, GRID_CELL), True)
    return memo[key]


def _surface_samples(vertices, faces, spacing, max_points, rng) -> np.ndarray:
    """About one point per ``spacing^2`` of area (at most ``max_points``) plus the vertices of a
    mesh with at most ``max_points`` of them (box corners), (M, 3)."""
    mesh = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces, np.int64), process=False,
                           validate=False)
    if mesh.area <= 0.0:
        return np.asarray(vertices, float)
    count = int(np.clip(mesh.area / spacing**2, 1, max_points))
    samples, _ = trimesh.sample.sample_surface(mesh, count, seed=int(rng.integers(2**31)))
    corners = mesh.vertices if len(mesh.vertices) <= max_points else np.empty((0, 3))
    return np.concatenate([samples, corners])
