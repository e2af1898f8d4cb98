"""Whether a contact surface can touch anything: the space in front of it and where it faces.

A face that another geometry element covers (a finger body's inner face under a fingertip pad
that is a separate ``<collision>`` element) cannot touch an object: ISF would pull it onto the
object and the pad in front of it would collide. :func:`blocked` tells, for points on a surface
with their outward normals, whether geometry lies within a few millimetres in front of them
(a segment along the normal meets a triangle) or encloses them (inside a closed element).
:func:`suggest_contacts <isf.registration.suggest_contacts>` keeps only faces left free;
:func:`contact_warnings` checks a tagged gripper's contact surfaces (``isf inspect``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

__all__ = ["FREE_DEPTH", "RECESS", "SURFACE_GAP", "blocked", "contact_warnings", "recess"]

SURFACE_GAP = 2e-4
"""Metres a test segment starts in front of its point (geometry touching the face is not in
front of it)."""

FREE_DEPTH = 5e-3
"""Metres in front of a contact point that must be free of geometry."""

_BLOCKED_SHARE = 0.5  # a surface with at least this share of blocked points is occluded
RECESS = 1e-3
"""Metres by which geometry of a contact's own link may stand in front of the contact (within
its outline) before the contact counts as recessed: a flat object would meet that geometry
first."""
_PAIRS_PER_CHUNK = 2_000_000  # segment-triangle pairs tested at once (memory ~ 100 bytes each)


def _crossings(origins: np.ndarray, directions: np.ndarray,
               triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where rays meet triangles (Moller-Trumbore): ``(ray, t)`` of every hit with ``t > 0``
    (``origins + t directions``; directions unit, so ``t`` in metres). origins, directions
    (R, 3); triangles (T, 3, 3)."""
    rays, params = [], []
    if len(triangles) == 0 or len(origins) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    a = triangles[:, 0]
    e1, e2 = triangles[:, 1] - a, triangles[:, 2] - a
    step = max(1, _PAIRS_PER_CHUNK // len(triangles))
    for lo in range(0, len(origins), step):
        o, d = origins[lo:lo + step, None, :], directions[lo:lo + step, None, :]
        p = np.cross(d, e2[None])
        det = np.einsum("rtj,rtj->rt", p, np.broadcast_to(e1[None], p.shape))
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - a[None]
            u = np.einsum("rtj,rtj->rt", s, p) * inv
            qv = np.cross(s, e1[None])
            v = np.einsum("rtj,rtj->rt", np.broadcast_to(d, qv.shape), qv) * inv
            t = np.einsum("rtj,tj->rt", qv, e2) * inv
            hit = (np.abs(det) > 1e-15) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
        r, k = np.nonzero(hit)
        rays.append(r + lo)
        params.append(t[r, k])
    return np.concatenate(rays), np.concatenate(params)


def blocked(points: np.ndarray, normals: np.ndarray, obstacles: Sequence[trimesh.Trimesh],
            depth: float = FREE_DEPTH, gap: float = SURFACE_GAP, *,
            enclosing: bool = True) -> np.ndarray:
    """Which points have geometry in front of them, (P,) bool.

    A point is blocked when the segment from ``gap`` to ``depth`` in front of it along its
    normal meets a triangle of ``obstacles``, or when its start lies inside an obstacle that is
    closed (watertight: an odd number of crossings along the normal; tested when
    ``enclosing``, which the mesh the points lie on does not need). All in one frame.

    Args:
        points: (P, 3), metres.
        normals: unit outward normals, (P, 3).
        obstacles: triangle meshes in the same frame.
        depth: metres in front of each point that must be free.
        gap: metres in front of each point where the test starts.
    """
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    out = np.zeros(len(points), bool)
    if len(points) == 0:
        return out
    origins = points + gap * normals
    ends = points + depth * normals
    lo, hi = np.minimum(origins, ends).min(axis=0), np.maximum(origins, ends).max(axis=0)
    for mesh in obstacles:
        triangles = np.asarray(mesh.triangles)
        bounds = np.asarray(mesh.bounds) if len(triangles) else None
        if bounds is None:
            continue
        inside_box = np.all((origins >= bounds[0]) & (origins <= bounds[1]), axis=1)
        if enclosing and mesh.is_watertight and inside_box.any():  # parity along the ray
            rays, t = _crossings(origins[inside_box], normals[inside_box], triangles)
            out[np.flatnonzero(inside_box)[np.bincount(rays, minlength=inside_box.sum()) % 2
                                           == 1]] = True
        near = np.all((triangles.max(axis=1) >= lo) & (triangles.min(axis=1) <= hi), axis=1)
        if near.any():  # the segments: only triangles that can reach them
            rays, t = _crossings(origins, normals, triangles[near])
            out[rays[t <= depth - gap]] = True
    return out


def recess(points: np.ndarray, normal: np.ndarray,
           geometry: Sequence[trimesh.Trimesh]) -> float:
    """How far ``geometry`` stands in front of a surface, metres (0 when nothing does).

    The surface is ``points`` (P, 3) facing ``normal`` (3,, unit); what counts of ``geometry``
    is its vertices and face centroids inside the surface's outline (its bounding rectangle in
    the plane across ``normal``, 0.1 mm wider), measured along ``normal`` from the surface's
    frontmost point.
    """
    normal = np.asarray(normal, float)
    across = np.linalg.svd(np.eye(3) - np.outer(normal, normal))[0][:, :2]  # the plane's axes
    flat = points @ across
    lo, hi = flat.min(axis=0) - 1e-4, flat.max(axis=0) + 1e-4
    front = float((points @ normal).max())
    worst = 0.0
    for mesh in geometry:
        probes = np.concatenate([np.asarray(mesh.vertices), np.asarray(mesh.triangles_center)])
        inside = np.all((probes @ across >= lo) & (probes @ across <= hi), axis=1)
        if inside.any():
            worst = max(worst, float((probes[inside] @ normal).max()) - front)
    return worst


def contact_warnings(gripper) -> list[str]:
    """Contact surfaces of ``gripper`` (:class:`isf.Gripper`) that cannot touch an object, at
    its initial configuration, one line each: a surface whose points mostly have gripper
    geometry within :data:`FREE_DEPTH` in front of them (another element covers it), and a
    surface whose mean normal faces away from every other surface (no object between the
    fingers is in front of it), and a surface that other geometry of its own link stands more
    than :data:`RECESS` in front of (:func:`recess`: a flat object meets that first). Empty for a
    sound gripper."""
    poses = gripper.link_poses(gripper.q_initial)
    obstacles = [trimesh.Trimesh(g.vertices @ poses[g.link][:3, :3].T + poses[g.link][:3, 3],
                                 g.faces, process=False) for g in gripper.geometries]
    placed = []
    for s in gripper.surfaces:
        T = poses[s.link]
        placed.append((s.points @ T[:3, :3].T + T[:3, 3], s.normals @ T[:3, :3].T))
    warnings = []
    for s, (points, normals) in zip(gripper.surfaces, placed):
        share = float(blocked(points, normals, obstacles).mean()) if len(points) else 0.0
        if share >= _BLOCKED_SHARE:
            warnings.append(
                f"contact {s.name!r}: {100 * share:.0f}% of its points have gripper geometry "
                f"within {1e3 * FREE_DEPTH:.0f} mm in front of them, so it cannot touch an "
                "object: tag the face in front (geometry=... names one element of the link)")
            continue
        mean = normals.mean(axis=0)
        own = [m for m, g in zip(obstacles, gripper.geometries) if g.link == s.link]
        depth = recess(points, mean / max(float(np.linalg.norm(mean)), 1e-300), own)
        if depth > RECESS:
            warnings.append(
                f"contact {s.name!r}: geometry of link {s.link!r} stands {1e3 * depth:.1f} mm in "
                "front of it, so a flat object meets that first and it cannot touch: tag the "
                "frontmost face (geometry=... names one element of the link)")
    centres = [points.mean(axis=0) for points, _ in placed]
    for k, (s, (_, normals)) in enumerate(zip(gripper.surfaces, placed)):
        others = [c for j, c in enumerate(centres) if j != k and gripper.surfaces[j].link != s.link]
        mean = normals.mean(axis=0)
        if not others or np.linalg.norm(mean) < 1e-9:
            continue
        if all((c - centres[k]) @ mean <= 0.0 for c in others):
            warnings.append(
                f"contact {s.name!r}: its normal faces away from every other contact surface at "
                "the initial configuration: flip its normal (or its faces, flip=true)")
    return warnings
