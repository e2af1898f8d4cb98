"""Turn an ``<isf:contact>`` tag into a :class:`~isf.gripper.model.ContactSurface`.

Steps: load the tag's geometry elements as triangle meshes in the link frame
(:func:`load_geometry`), keep the faces that pass the normal cone and the box
(:func:`select_faces`), sample points uniformly by area with a seed derived from
the surface name and order them by farthest-point sampling (:func:`sample_faces`).

Outward check (:func:`orientation_problem`). Face normals follow the triangle
winding, so a wrongly wound mesh or a wrong ``flip`` turns them inward. For a
*closed*, consistently wound element mesh the outward side is known exactly:
its enclosed (signed) volume is positive iff its normals point outward. For an
open element no inside exists, so a heuristic is used: the area-weighted mean of
``n . (p - c) / |p - c|`` over the selected faces (``p`` face centroid, ``c`` the
centroid of the link's geometry) must not be below ``-0.1``; a flat sheet through
``c`` scores about 0 and passes.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ..exceptions import GeometryLoadError, SurfaceSelectionError
from .mesh_paths import PackageDirs, resolve_mesh_path
from .model import ContactSurface
from .urdf_tags import ContactTag, GeometryElement, LinkElement

__all__ = [
    "FaceSelection",
    "GeometryLoadError",
    "SurfaceSelectionError",
    "farthest_point_order",
    "load_geometry",
    "orientation_problem",
    "sample_faces",
    "select_faces",
    "surface_seed",
    "tag_elements",
]

_CYLINDER_SECTIONS = 48
_SPHERE_SUBDIVISIONS = 3
_OPEN_SHEET_THRESHOLD = -0.1


# ------------------------------------------------------------------ loading
def _read_mesh_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False, skip_materials=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise GeometryLoadError(
            f"cannot read mesh {path} ({exc}): convert it to STL or OBJ", path=path, shape="mesh"
        ) from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise GeometryLoadError(
            f"mesh {path} holds no triangles: export it as a triangle mesh", path=path, shape="mesh"
        )
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def load_geometry(
    geom: GeometryElement,
    urdf_dir: str | Path,
    package_dirs: PackageDirs | None = None,
    cache: dict[Path, tuple[np.ndarray, np.ndarray]] | None = None,
) -> trimesh.Trimesh:
    """A geometry element as a triangle mesh in its link's frame.

    ``<mesh scale>`` and the element's ``<origin>`` are applied; a mirroring scale
    keeps the faces outward. Vertices are merged by position (texture seams too).

    Args:
        geom: the element.
        urdf_dir: folder of the URDF, for relative mesh paths.
        package_dirs: optional ``{package: folder}`` map for ``package://`` paths.
        cache: optional ``{file: (vertices, faces)}`` shared between calls.

    Raises:
        MeshNotFoundError: the mesh file does not exist (lists the paths tried).
        GeometryLoadError: unreadable mesh or unsupported shape.
    """
    if geom.shape == "mesh" and geom.filename:
        path = resolve_mesh_path(geom.filename, urdf_dir, package_dirs, geom.link)
        if cache is not None and path in cache:
            vertices, faces = cache[path]
        else:
            vertices, faces = _read_mesh_file(path)
            if cache is not None:
                cache[path] = (vertices, faces)
        vertices = vertices * geom.scale
        if np.prod(geom.scale) < 0:
            faces = faces[:, ::-1]
    elif geom.shape == "box":
        prim = trimesh.creation.box(extents=geom.size)
        vertices, faces = prim.vertices, prim.faces
    elif geom.shape == "cylinder":
        prim = trimesh.creation.cylinder(
            radius=geom.radius, height=geom.length, sections=_CYLINDER_SECTIONS
        )
        vertices, faces = prim.vertices, prim.faces
    elif geom.shape == "sphere":
        prim = trimesh.creation.icosphere(subdivisions=_SPHERE_SUBDIVISIONS, radius=geom.radius)
        vertices, faces = prim.vertices, prim.faces
    else:
        raise GeometryLoadError(
            f"unsupported geometry <{geom.shape}>: use a mesh, box, cylinder or sphere",
            shape=geom.shape,
        )
    T = geom.T_link_geom
    vertices = np.asarray(vertices, dtype=float) @ T[:3, :3].T + T[:3, 3]
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=True)


def tag_elements(tag: ContactTag, link: LinkElement) -> list[GeometryElement]:
    """The geometry elements a tag reads: ``geometry`` by name, else all of ``source``.

    Raises:
        SurfaceSelectionError: the link has no such element.
    """
    elements = link.collisions if tag.source == "collision" else link.visuals
    if not elements:
        other = "visual" if tag.source == "collision" else "collision"
        raise SurfaceSelectionError(
            f"contact {tag.name!r}: link {tag.link!r} has no <{tag.source}> element: "
            f'add one or set source="{other}"',
            contact=tag.name,
            link=tag.link,
        )
    if tag.geometry is None:
        return list(elements)
    fallback = {f"{tag.link}_{e.index}": e for e in elements}
    chosen = [e for e in elements if e.name == tag.geometry] or (
        [fallback[tag.geometry]] if tag.geometry in fallback else []
    )
    if not chosen:
        names = ", ".join(repr(e.name) for e in elements)
        raise SurfaceSelectionError(
            f"contact {tag.name!r}: link {tag.link!r} has no <{tag.source}> named "
            f"{tag.geometry!r}; its {tag.source} elements are {names}",
            contact=tag.name,
            link=tag.link,
        )
    return chosen


# ---------------------------------------------------------------- selection
@dataclass(frozen=True, eq=False)
class FaceSelection:
    """The faces a tag keeps, in the link frame.

    Attributes:
        triangles: corner positions, shape (F, 3, 3), metres.
        normals: unit contact-side normals (flipped if the tag says so), (F, 3).
        areas: face areas, shape (F,), m^2.
        element: index of the source mesh of each face, shape (F,).
    """

    triangles: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    element: np.ndarray

    @property
    def area(self) -> float:
        """Total area of the selected faces, m^2."""
        return float(self.areas.sum())


def select_faces(tag: ContactTag, meshes: Sequence[trimesh.Trimesh]) -> FaceSelection:
    """Keep the faces of ``meshes`` that pass the tag's normal cone and box.

    Raises:
        SurfaceSelectionError: no face (of positive area) is left.
    """
    tris = np.concatenate([np.asarray(m.triangles, dtype=float) for m in meshes])
    element = np.concatenate([np.full(len(m.faces), k) for k, m in enumerate(meshes)])
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(doubled, 1e-300)[:, None]
    if tag.flip:
        normals = -normals
    keep = doubled > 0
    n_all = int(keep.sum())
    if tag.normal is not None:
        keep &= normals @ tag.normal >= np.cos(tag.max_angle) - 1e-12
    n_cone = int(keep.sum())
    if tag.box_min is not None or tag.box_max is not None:
        centroids = tris.mean(axis=1)
        lo = np.full(3, -np.inf) if tag.box_min is None else tag.box_min
        hi = np.full(3, np.inf) if tag.box_max is None else tag.box_max
        keep &= np.all((centroids >= lo) & (centroids <= hi), axis=1)
    if not keep.any():
        raise SurfaceSelectionError(
            f"contact {tag.name!r}: the selection keeps no face ({n_all} faces, {n_cone} within "
            f"the normal cone, 0 also in the box): check normal/max_angle/box_min/box_max, "
            f"which are in link {tag.link!r}'s frame",
            contact=tag.name,
            link=tag.link,
        )
    return FaceSelection(tris[keep], normals[keep], 0.5 * doubled[keep], element[keep])


# ----------------------------------------------------------------- sampling
def surface_seed(name: str) -> int:
    """A fixed 64-bit seed derived from a surface name (stable across runs and platforms)."""
    return int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")


def farthest_point_order(points: np.ndarray, start: int) -> np.ndarray:
    """Farthest-point ordering of ``points`` (N, 3) starting at index ``start``.

    Returns:
        a permutation of ``range(N)``; each next index is the point farthest from
        all earlier ones.
    """
    n = len(points)
    order = np.empty(n, dtype=np.int64)
    order[0] = start
    sq = np.einsum("ij,ij->i", points, points)
    dist = sq - 2.0 * points @ points[start] + sq[start]
    for i in range(1, n):
        j = int(np.argmax(dist))
        order[i] = j
        np.minimum(dist, sq - 2.0 * points @ points[j] + sq[j], out=dist)
    return order


def sample_faces(name: str, link: str, selection: FaceSelection, n: int) -> ContactSurface:
    """Sample ``n`` points uniformly by area on the selected faces.

    The seed comes from ``name``; the points are in farthest-point order starting
    with the sample nearest the area-weighted centroid of the faces.

    Returns:
        the :class:`ContactSurface` (points and normals in the link frame).
    """
    rng = np.random.default_rng(surface_seed(name))
    weights = selection.areas / selection.areas.sum()
    face = np.minimum(np.searchsorted(np.cumsum(weights), rng.random(n)), len(weights) - 1)
    u, v = rng.random((2, n))
    outside = u + v > 1.0
    u[outside], v[outside] = 1.0 - u[outside], 1.0 - v[outside]
    tri = selection.triangles[face]
    points = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    centroid = weights @ selection.triangles.mean(axis=1)
    start = int(np.argmin(np.sum((points - centroid) ** 2, axis=1)))
    order = farthest_point_order(points, start)
    return ContactSurface(
        name=name,
        link=link,
        points=points[order],
        normals=selection.normals[face][order],
        area=selection.area,
    )


def orientation_problem(
    tag: ContactTag,
    meshes: Sequence[trimesh.Trimesh],
    elements: Sequence[GeometryElement],
    selection: FaceSelection,
    link_center: np.ndarray,
) -> str | None:
    """A message if the selected normals point into the link, else None (see module doc).

    Args:
        tag: the contact tag.
        meshes: the tag's element meshes, link frame.
        elements: the matching geometry elements (for names in the message).
        selection: the faces :func:`select_faces` kept.
        link_center: centroid of the link's geometry, link frame, shape (3,).
    """
    inward = []
    for k in np.unique(selection.element):
        mesh, faces = meshes[k], selection.element == k
        if mesh.is_watertight and mesh.is_winding_consistent:
            bad = (mesh.volume < 0) != tag.flip
        else:
            rel = selection.triangles[faces].mean(axis=1) - link_center
            cos = np.sum(selection.normals[faces] * rel, axis=1) / np.maximum(
                np.linalg.norm(rel, axis=1), 1e-12
            )
            bad = np.average(cos, weights=selection.areas[faces]) < _OPEN_SHEET_THRESHOLD
        if bad:
            inward.append(elements[k].name)
    if not inward:
        return None
    fix = 'remove flip="true"' if tag.flip else 'set flip="true" or fix the mesh winding'
    return (
        f"contact {tag.name!r}: the normals of {', '.join(map(repr, inward))} point into "
        f"link {tag.link!r}: {fix}"
    )
