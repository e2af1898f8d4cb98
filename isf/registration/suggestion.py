"""Suggest the contact surfaces (:func:`suggest_contacts`) and the approach direction
(:func:`suggest_approach`) of a stock gripper URDF.

:func:`suggest_contacts` proposes one contact per fingertip: the leaf links of the kinematic tree
below a movable joint, each with the face normal that faces the other fingertips at the initial
configuration, on faces that nothing covers. Its heuristics are documented on the function;
the result is a list of ordinary :class:`ContactSpec` values to accept or edit.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin
import trimesh

from ..exceptions import GeometryLoadError, MeshNotFoundError, ModelBuildError, RegistrationError
from ..gripper.mesh_paths import PackageDirs
from ..gripper.surface_sampling import load_geometry, select_faces
from ..gripper.urdf_tags import ContactTag, TaggedURDF
from ._urdf_source import (
    Posed,
    face_areas,
    face_normals,
    initial_tags,
    parse_urdf,
    pose_urdf,
    read_urdf,
)
from .occlusion import blocked
from .spec import ContactSpec

__all__ = ["SuggestedTCP", "suggest_approach", "suggest_closing", "suggest_contacts", "suggest_tcp"]

log = logging.getLogger(__name__)

_MOVABLE = ("revolute", "prismatic", "continuous")
# suggest_contacts: faces considered around the direction to the other fingertips, radians
_SEARCH_ANGLE = 0.8
# faces whose normals lie within this angle form one flat cluster, radians
_CLUSTER_ANGLE = 0.1
# a cluster holding at least this share of the considered area counts as a flat pad
_FLAT_SHARE = 0.5
# a leaf is dropped when another leaf has more movable joints and is this much farther away
_SIDE_LINK_RATIO = 0.75
_MAX_CLUSTER_SEEDS = 400
# cone half-angles of suggested contacts: a flat pad's faces only; a cap of a rounded tip
_PAD_ANGLE = 0.3
_TIP_ANGLE = 0.5
# a pad is cut along a link axis only if that axis is this close to the approach, radians
_DISTAL_AXIS_ANGLE = 0.35
_BOX_MARGIN = 0.01  # metres added around the link geometry on the box's free axes
# a face counts as covered when this share of its test points has geometry in front of it
_COVERED_SHARE = 0.5
# faces of a pad lying this much behind its frontmost face (along the normal) cannot touch
_BEHIND = 1e-3


@dataclass(frozen=True, eq=False)
class _Fingertip:
    link: str
    source: str
    meshes: tuple[trimesh.Trimesh, ...]  # link frame, one per geometry element
    elements: tuple[str, ...]  # the elements' names
    centroid: np.ndarray  # gripper frame, (3,)
    neighbours: tuple[trimesh.Trimesh, ...]  # link frame: geometry of the adjacent links


def _movable_depth(doc: TaggedURDF) -> dict[str, int]:
    """Number of movable joints between the root and every link."""
    parent = {j.child: j for j in doc.joints.values()}
    depth: dict[str, int] = {}
    for link in doc.links:
        n, x, seen = 0, link, set()
        while x in parent and x not in seen:
            seen.add(x)
            n += parent[x].type in _MOVABLE
            x = parent[x].parent
        depth[link] = n
    return depth


def _surface_centroid(meshes: Sequence[trimesh.Trimesh]) -> np.ndarray:
    tris = np.concatenate([np.asarray(m.triangles) for m in meshes])
    areas = face_areas(tris)
    if areas.sum() <= 0:
        return tris.reshape(-1, 3).mean(axis=0)
    return areas @ tris.mean(axis=1) / areas.sum()


def _fingertip_candidates(doc: TaggedURDF, links: Sequence[str] | None) -> list[str]:
    """Leaf links below a movable joint (or ``links``), each replaced by its nearest
    ancestor with geometry when it has none itself."""
    parent = {j.child: j.parent for j in doc.joints.values()}
    depth = _movable_depth(doc)
    if links is not None:
        missing = [name for name in links if name not in doc.links]
        if missing:
            raise RegistrationError(
                f"links {missing} do not exist in the URDF; links: {', '.join(doc.links)}"
            )
        return list(dict.fromkeys(links))
    has_child = {j.parent for j in doc.joints.values()}
    out: dict[str, None] = {}
    for leaf in doc.links:
        if leaf in has_child or depth[leaf] == 0:
            continue
        x = leaf
        while not (doc.links[x].collisions or doc.links[x].visuals) and x in parent:
            x = parent[x]
        if depth[x] > 0 and (doc.links[x].collisions or doc.links[x].visuals):
            out.setdefault(x, None)
    return list(out)


def _fingertips(
    urdf_path: str | Path,
    links: Sequence[str] | None,
    initial: Mapping[str, float] | None,
    package_dirs: PackageDirs | None,
) -> tuple[Posed, list[_Fingertip]]:
    src, text = read_urdf(urdf_path)
    doc = parse_urdf(text, src)
    try:
        posed = pose_urdf(text, doc, initial_tags(initial))
    except ModelBuildError as exc:
        raise RegistrationError(f"{src}: {exc}", source=src) from exc
    cache: dict = {}
    tips = []
    for name in _fingertip_candidates(doc, links):
        link = doc.links[name]
        source = "collision" if link.collisions else "visual"
        elements = link.collisions or link.visuals
        try:
            meshes = tuple(load_geometry(e, src.parent, package_dirs, cache) for e in elements)
            neighbours = _neighbour_geometry(doc, posed, name, src.parent, package_dirs, cache)
        except (GeometryLoadError, MeshNotFoundError) as exc:
            raise RegistrationError(f"link {name!r}: {exc}", source=src) from exc
        if not meshes:
            raise RegistrationError(
                f"link {name!r} has no geometry to put a contact on: choose other links",
                source=src,
            )
        T = posed.poses[name]
        centroid = T[:3, :3] @ _surface_centroid(meshes) + T[:3, 3]
        tips.append(_Fingertip(name, source, meshes, tuple(e.name for e in elements), centroid,
                               neighbours))
    if links is None:
        tips = _drop_side_links(tips, _movable_depth(doc))
    if len(tips) < 2:
        found = ", ".join(t.link for t in tips) or "none"
        raise RegistrationError(
            f"{src}: found {len(tips)} fingertip link(s) ({found}); a grasp needs at least two: "
            "pass links=[...] naming the fingertip links",
            source=src,
        )
    return posed, tips


def _neighbour_geometry(doc: TaggedURDF, posed: Posed, name: str, folder: Path,
                        package_dirs: PackageDirs | None,
                        cache: dict) -> tuple[trimesh.Trimesh, ...]:
    """The geometry of the links joined to link ``name`` (its parent and children), at the
    initial configuration, in ``name``'s frame (collision geometry, else visual)."""
    adjacent = [j.parent for j in doc.joints.values() if j.child == name]
    adjacent += [j.child for j in doc.joints.values() if j.parent == name]
    T_link_root = np.linalg.inv(posed.poses[name])
    out = []
    for other in dict.fromkeys(adjacent):
        if other not in doc.links or other not in posed.poses:
            continue
        T = T_link_root @ posed.poses[other]
        for element in doc.links[other].collisions or doc.links[other].visuals:
            mesh = load_geometry(element, folder, package_dirs, cache)
            out.append(trimesh.Trimesh(np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3],
                                       mesh.faces, process=False))
    return tuple(out)


def _covered(tris: np.ndarray, normals: np.ndarray, own: trimesh.Trimesh,
             obstacles: Sequence[trimesh.Trimesh]) -> np.ndarray:
    """Which faces (F, 3, 3) of the mesh ``own`` with unit ``normals`` (F, 3) have geometry in
    front of most of their test points (the centroid and a point between it and each corner),
    (F,) bool: ``own`` or ``obstacles`` in front, or inside one of ``obstacles``
    (:func:`isf.registration.occlusion.blocked`)."""
    centroid = tris.mean(axis=1)
    points = np.concatenate([centroid[:, None], 0.5 * (tris + centroid[:, None])], axis=1)
    points, normals = points.reshape(-1, 3), np.repeat(normals, 4, axis=0)
    hits = blocked(points, normals, [own], enclosing=False) | blocked(points, normals, obstacles)
    return hits.reshape(-1, 4).mean(axis=1) >= _COVERED_SHARE


def _drop_side_links(tips: list[_Fingertip], depth: dict[str, int]) -> list[_Fingertip]:
    """Drop leaves of linkages (e.g. a four-bar's inner knuckle): a leaf with fewer movable
    joints than another leaf and much nearer to the root than it."""
    reach = {t.link: float(np.linalg.norm(t.centroid)) for t in tips}
    keep = []
    for t in tips:
        beaten = [
            u.link
            for u in tips
            if depth[u.link] > depth[t.link] and reach[t.link] < _SIDE_LINK_RATIO * reach[u.link]
        ]
        if beaten:
            log.info("not a fingertip: %s (nearer than %s, fewer joints)", t.link, beaten[0])
        else:
            keep.append(t)
    return keep


class _Facing(NamedTuple):
    """What :func:`_facing_normal` found.

    Attributes:
        normal: the contact normal, link frame, (3,).
        flat: whether it is a flat pad's.
        pad: the pad's faces (those that can touch: free in front and frontmost), (F,) bool
            over the meshes' faces in order; none for a rounded tip.
    """

    normal: np.ndarray
    flat: bool
    pad: np.ndarray


def _facing_normal(
    meshes: Sequence[trimesh.Trimesh], direction: np.ndarray,
    neighbours: Sequence[trimesh.Trimesh] = ()
) -> _Facing:
    """The face normal of ``meshes`` (a link's elements, link frame) that faces ``direction``,
    and whether it belongs to a flat pad.

    Faces within ``_SEARCH_ANGLE`` of ``direction`` are considered, except those covered by
    geometry in front of them (the link's elements and ``neighbours``, the adjacent links'
    geometry in the link frame: :func:`_covered`); the largest cluster of nearly parallel normals (a flat pad)
    gives the answer when it holds at least half their area, and the pad is that cluster's
    faces lying within 1 mm of its frontmost one along the normal (a face further back cannot
    touch a flat object before the one in front). Otherwise (a rounded tip) ``direction``
    itself is returned.
    """
    tris = np.concatenate([np.asarray(m.triangles) for m in meshes])
    element = np.repeat(np.arange(len(meshes)), [len(m.faces) for m in meshes])
    normals, areas = face_normals(tris), face_areas(tris)
    near = (normals @ direction >= math.cos(_SEARCH_ANGLE)) & (areas > 0)
    for k, mesh in enumerate(meshes):
        candidates = np.flatnonzero(near & (element == k))
        others = [m for j, m in enumerate(meshes) if j != k] + list(neighbours)
        if len(candidates):
            near[candidates[_covered(tris[candidates], normals[candidates], mesh, others)]] = False
    none = np.zeros(len(tris), bool)
    if not near.any():
        return _Facing(direction, False, none)
    n, a = normals[near], areas[near]
    seeds = np.arange(len(n))
    if len(seeds) > _MAX_CLUSTER_SEEDS:
        seeds = np.argsort(-a)[:_MAX_CLUSTER_SEEDS]
    support = (n[seeds] @ n.T >= math.cos(_CLUSTER_ANGLE)) @ a
    best = seeds[int(np.argmax(support))]
    members = n @ n[best] >= math.cos(_CLUSTER_ANGLE)
    if a[members].sum() < _FLAT_SHARE * a.sum():
        return _Facing(direction, False, none)
    mean = a[members] @ n[members]
    normal = mean / np.linalg.norm(mean)
    pad = np.flatnonzero(near)[members]
    height = tris[pad].mean(axis=1) @ normal
    out = none.copy()
    out[pad[height >= height.max() - _BEHIND]] = True
    return _Facing(normal, True, out)


def _closing_direction(posed: Posed, link: str, toward: np.ndarray) -> np.ndarray:
    """``toward`` (unit, gripper frame) without its component along the axis of the revolute
    joint that moves ``link`` last, (3,): a rounded fingertip faces the side its finger curls
    towards, not sideways out of the finger (on a hand the centroid of the fingertips lies off to
    the side of most fingers). Unchanged when that joint is prismatic or the rest is too small.
    """
    model = posed.model
    fid = model.getFrameId(link)
    joint = model.frames[fid].parentJoint
    if joint == 0 or model.joints[joint].nv == 0:
        return toward
    J = pin.computeFrameJacobian(model, model.createData(), posed.q, fid, pin.LOCAL_WORLD_ALIGNED)
    column = J[3:, model.joints[joint].idx_v]
    if np.linalg.norm(column) < 1e-9:  # a prismatic joint turns nothing
        return toward
    axis = column / np.linalg.norm(column)
    rest = toward - (toward @ axis) * axis
    norm = float(np.linalg.norm(rest))
    return rest / norm if norm > 0.2 else toward


def _surface_name(link: str) -> str:
    return link if link.endswith(("pad", "tip")) else f"{link}_pad"


def _distal_box(
    spec: ContactSpec, meshes: Sequence[trimesh.Trimesh], reach: np.ndarray, fraction: float
) -> ContactSpec:
    """Restrict a flat pad to its faces that lie wholly in the distal ``fraction`` of its length.

    ``reach`` is the approach direction in the link frame (unit). The cut is a bound on the link
    axis nearest ``reach``, written as ``box_min``/``box_max`` (other axes: the link's geometry
    bounds widened by 1 cm). A box keeps faces by their centroids, so the bound sits between the
    centroids of the distal faces and that of the first face reaching further back; vendor
    collision meshes often hold long sliver faces, which this leaves out. Nothing changes when
    no link axis lies within 20 degrees of ``reach`` or when the most distal face already
    reaches further back (a box face of two triangles).
    """
    axis = int(np.argmax(np.abs(reach)))
    if abs(reach[axis]) < math.cos(_DISTAL_AXIS_ANGLE):
        return spec
    axis_n = np.asarray(spec.normal) / np.linalg.norm(spec.normal)
    tag = ContactTag(spec.name, spec.link, normal=axis_n, max_angle=spec.max_angle)
    tris = select_faces(tag, meshes).triangles
    sign = 1.0 if reach[axis] > 0 else -1.0
    along = sign * tris[:, :, axis]  # larger is more distal
    limit = along.max() - fraction * (along.max() - along.min()) - 1e-9
    centroids = along.mean(axis=1)
    order = np.argsort(-centroids)
    inside = along[order].min(axis=1) >= limit
    n_keep = len(order) if inside.all() else int(np.argmin(inside))
    if n_keep == 0 or n_keep == len(order):
        return spec
    first_out, last_in = centroids[order[n_keep]], centroids[order[n_keep - 1]]
    cut = round(0.5 * (first_out + last_in), 4)  # a readable value between the two centroids
    if not first_out < cut < last_in:
        cut = 0.5 * (first_out + last_in)
    verts = np.concatenate([np.asarray(m.vertices) for m in meshes])
    bound_lo = np.floor(1e3 * (verts.min(axis=0) - _BOX_MARGIN)) / 1e3
    bound_hi = np.ceil(1e3 * (verts.max(axis=0) + _BOX_MARGIN)) / 1e3
    if sign > 0:
        bound_lo[axis] = cut
    else:
        bound_hi[axis] = -cut
    return replace(spec, box_min=tuple(bound_lo), box_max=tuple(bound_hi))


def suggest_contacts(
    urdf_path: str | Path,
    *,
    links: Sequence[str] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
    points: int = 256,
    max_angle: float | None = None,
    tip_fraction: float = 0.5,
) -> list[ContactSpec]:
    """Propose one contact surface per fingertip, facing the other fingertips.

    Fingertips: the leaf links of the kinematic tree that lie below at least one movable
    joint (a leaf without geometry is replaced by its nearest ancestor with some). A leaf
    that has fewer movable joints than another leaf and is less than 0.75 times as far from
    the root is taken for a linkage side link (the inner knuckle of a four-bar finger) and
    dropped. ``links`` overrides all of this.

    Facing direction: at the initial configuration (``isf:initial`` tags, then ``initial``,
    else mid-limits), the direction from the fingertip's geometry centroid to the centroid
    of all fingertips, in the link frame. The contact's ``normal`` is the mean normal of the
    largest flat cluster of faces within 46 degrees of it (a pad); when no cluster holds half
    of those faces' area (a rounded tip) it is that direction without its component along
    the axis of the revolute joint that moves the tip last, i.e. the side the finger curls
    towards (on a hand the centroid lies off to the side of most fingers; a cap facing
    sideways would put the distal link's edge into the object). The cone half-angle
    ``max_angle`` is 0.3 rad for a flat pad (its faces only) and 0.5 rad for a rounded tip
    (a cap of it). Collision geometry is used when the link has any, else visual geometry.

    Faces that cannot touch are never chosen: every geometry element of the link is
    considered, and a face with geometry within 5 mm in front of most of its test points
    (another element of the link, an element of a link joined to it, or its own mesh) or
    inside a closed element is left out (:mod:`isf.registration.occlusion`); of a flat pad,
    only the faces within 1 mm of its frontmost one along the normal count (a body face behind
    a fingertip pad meets a flat object after the pad). When the link has several elements and
    those faces belong to one of them, the contact names it (``geometry``), so the faces of the
    other elements are not sampled, and the ``tip_fraction`` cut below applies to that
    element.

    Fingertip part of a flat pad: ISF pulls a contact surface onto the object as a whole, so a
    pad as long as the finger (Franka hand) puts the palm into any object longer than the pad.
    A flat pad is therefore cut to the ``tip_fraction`` of its length at its distal end (along
    the approach direction, the root origin to the fingertips' centroid): only its faces lying
    wholly in that part are kept, with a ``box_min``/``box_max``. A pad whose most distal face
    already reaches further back (a box face of two triangles) is kept whole.

    Args:
        urdf_path: the URDF (tagged or not).
        links: fingertip links to use instead of the automatic choice.
        initial: initial joint values by name, metres or radians.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
        points: ``points`` of every proposed contact.
        max_angle: ``max_angle`` of every proposed contact, radians; None: automatic.
        tip_fraction: share of a flat pad's length kept at its distal end, in (0, 1];
            1 keeps the whole pad.

    Returns:
        one :class:`ContactSpec` per fingertip, named after its link (``<link>_pad`` unless
        the link name already ends in ``pad`` or ``tip``).

    Raises:
        RegistrationError: unreadable URDF or meshes, unknown ``links``, fewer than two
            fingertips, fingertips that coincide at the initial configuration, or a bad
            ``tip_fraction``.
    """
    if not 0.0 < tip_fraction <= 1.0:
        raise RegistrationError(f"tip_fraction={tip_fraction!r} must lie in (0, 1]")
    posed, tips = _fingertips(urdf_path, links, initial, package_dirs)
    center = np.mean([t.centroid for t in tips], axis=0)
    reach = center / max(float(np.linalg.norm(center)), 1e-300)  # root origin -> fingertips
    out = []
    for t in tips:
        toward = center - t.centroid
        dist = float(np.linalg.norm(toward))
        if dist < 1e-4:
            raise RegistrationError(
                f"fingertip {t.link!r} sits at the centroid of all fingertips at the initial "
                "configuration, so it faces no direction: pass initial={...} with the gripper open"
            )
        R = posed.poses[t.link][:3, :3]
        element = np.repeat(np.arange(len(t.meshes)), [len(m.faces) for m in t.meshes])
        normal, flat, pad = _facing_normal(t.meshes, R.T @ toward / dist, t.neighbours)
        if not flat:  # a rounded tip: face the side the finger closes towards
            normal = R.T @ _closing_direction(posed, t.link, toward / dist)
        auto_angle = _PAD_ANGLE if flat else _TIP_ANGLE
        holding = np.unique(element[pad])  # the elements holding the pad
        geometry = t.elements[holding[0]] if len(t.meshes) > 1 and len(holding) == 1 else None
        spec = ContactSpec(
            name=_surface_name(t.link),
            link=t.link,
            geometry=geometry,
            source=t.source,
            normal=tuple(np.round(normal, 4)),
            max_angle=auto_angle if max_angle is None else max_angle,
            points=points,
        )
        if flat and tip_fraction < 1.0 and np.linalg.norm(center) > 1e-6:
            kept = t.meshes if geometry is None else (t.meshes[holding[0]],)
            spec = _distal_box(spec, kept, R.T @ reach, tip_fraction)
        out.append(spec)
    return out


def suggest_approach(
    urdf_path: str | Path,
    *,
    palm_link: str | None = None,
    links: Sequence[str] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
) -> tuple[float, float, float]:
    """Propose ``<isf:gripper approach>``: from the palm link origin toward the fingertips.

    Args:
        urdf_path: the URDF.
        palm_link: the link the direction is expressed in; default the root link.
        links, initial, package_dirs: as for :func:`suggest_contacts`.

    Returns:
        unit direction in the ``palm_link`` frame, from its origin to the centroid of the
        fingertips' geometry at the initial configuration.

    Raises:
        RegistrationError: as :func:`suggest_contacts`, or an unknown ``palm_link``.
    """
    palm, v = _fingertip_centre(urdf_path, palm_link, links, initial, package_dirs)
    norm = float(np.linalg.norm(v))
    if norm < 1e-6:
        raise RegistrationError(
            f"the fingertips surround the origin of {palm!r}: give approach=... yourself"
        )
    return tuple(float(x) for x in v / norm)


@dataclass(frozen=True)
class SuggestedTCP:
    """A proposed ``<isf:gripper tcp_link tcp_origin>``.

    Attributes:
        link: the link the point is given in (the palm link).
        origin: the point in that link's frame, metres, (x, y, z); the TCP's axes are the link's.
    """

    link: str
    origin: tuple[float, float, float]


def suggest_closing(tagged_urdf: str | Path, *, package_dirs: PackageDirs | None = None
                    ) -> dict[str, float]:
    """Propose each actuated joint's closing sign (``<isf:closing>``) from the contact normals.

    A finger closes along its contact surface's outward normal: the sign of a joint is that of
    the contact points' motion along their normals per unit of the joint
    (:meth:`isf.Gripper.suggested_closing`, at the initial configuration).

    Args:
        tagged_urdf: a URDF with its ``<isf:contact>`` tags (e.g. written by :func:`tag_urdf`).
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.

    Returns:
        ``{joint: +1.0 or -1.0}`` for every actuated joint that moves a contact surface.

    Raises:
        GripperDescriptionError: the tagged URDF does not load.
    """
    from ..gripper.loading import load_gripper

    return load_gripper(tagged_urdf, package_dirs=package_dirs).suggested_closing()


def suggest_tcp(
    urdf_path: str | Path,
    *,
    palm_link: str | None = None,
    links: Sequence[str] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
) -> SuggestedTCP:
    """Propose the tool-centre point: between the fingertips, in the palm link's frame.

    Args:
        urdf_path, palm_link, links, initial, package_dirs: as for :func:`suggest_approach`.

    Returns:
        the centroid of the fingertips' geometry at the initial configuration, in the
        ``palm_link`` frame (default the root link), with that link's axes.

    Raises:
        RegistrationError: as :func:`suggest_approach`.
    """
    palm, centre = _fingertip_centre(urdf_path, palm_link, links, initial, package_dirs)
    return SuggestedTCP(palm, tuple(float(round(x, 6)) for x in centre))


def _fingertip_centre(urdf_path: str | Path, palm_link: str | None, links: Sequence[str] | None,
                      initial: Mapping[str, float] | None, package_dirs: PackageDirs | None
                      ) -> tuple[str, np.ndarray]:
    """The palm link (``palm_link`` or the root link) and the centroid of the fingertips'
    geometry at the initial configuration in its frame, metres, (3,).

    Raises:
        RegistrationError: as :func:`suggest_contacts`, or an unknown ``palm_link``.
    """
    posed, tips = _fingertips(urdf_path, links, initial, package_dirs)
    palm = palm_link or posed.doc.root_link
    if palm not in posed.poses:
        raise RegistrationError(
            f"palm_link {palm!r} does not exist; links: {', '.join(posed.doc.links)}"
        )
    T = posed.poses[palm]
    return palm, T[:3, :3].T @ (np.mean([t.centroid for t in tips], axis=0) - T[:3, 3])
