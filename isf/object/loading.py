"""Load an object mesh or point cloud into an :class:`~isf.object.surface.ObjectSurface`.

Every source ends as about 3000 evenly spaced surface points (the paper downsampled its
objects to about 2000) with unit outward normals, in metres, in the frame of the input.

Meshes (STL, OBJ, PLY with faces, OFF, GLB/GLTF, a ``trimesh.Trimesh`` or ``trimesh.Scene``):

* every geometry of a scene is placed with its scene transform and all are kept (multi-body);
* vertices are merged by position, ignoring the UV and normal seams that make textured
  OBJ files look open; collapsed and duplicated triangles are dropped;
* each watertight body gets a consistent winding with positive volume, so its face normals
  point outward; open bodies (scans with holes) keep the winding of the file;
* points are drawn at random by area (fixed seed) and thinned to one per voxel (the sample
  nearest the voxel's mean), which spaces them evenly on the surface; each point carries the
  normal of the triangle it lies on. The scaled, cleaned mesh is kept for collision checks.

Point clouds (PLY without faces, PCD ascii/binary, XYZ text, NPY, an (N, 3) or (N, 6) array):

* voxel downsampling averages the points (and given normals) in each voxel;
* missing normals are estimated by PCA over the k nearest neighbours and oriented
  consistently by propagation over a minimum spanning tree of the k-NN graph (weight
  ``1 - |n_i . n_j|``, Hoppe et al. 1992). Each connected part is then turned outward: by
  default its seed, the point farthest from the part's centroid, gets the normal pointing away
  from that centroid (right for a whole object). For a partial cloud from a camera, pass
  ``viewpoint=`` (the camera position): each part is then turned so its normals face the
  camera (a vote over all its points, robust at grazing angles), which is also right for views
  into concave shapes (the inside of a bowl) where the centroid rule fails;
* normals given by the file are trusted (only normalised); with a viewpoint, each one that
  faces away from the camera is flipped (PCL's convention).

Automatic resolution (``voxel_size=None``): the voxel size ``h`` is searched so the result
has about 3000 points. It starts from ``h = sqrt(1.5 * A / 3000)`` (``A`` the mesh area;
a plane cuts on average ``1.5 A / h^2`` cubic voxels) or ``diagonal / 50`` for a cloud, and
is refined up to six times with ``h <- h * sqrt(n(h) / 3000)`` until ``n`` lies in
[2500, 3500] (the count of a surface scales as ``1 / h^2``). A cloud that already has at most
4000 points is kept as it is, and its ``spacing`` is then the median nearest-neighbour
distance. ``max_points`` caps the result by growing the voxel size further.

Layout: this module holds the public entry, its constants, the checks of arguments and data,
and the resolution rule. Reading is in :mod:`isf.object._readers` (with
:mod:`isf.object._obj_reader` and :mod:`isf.object._pcd_reader`), mesh cleaning and sampling in
:mod:`isf.object.mesh_sampling`, cloud downsampling and normals in :mod:`isf.object._normals`,
on top of :mod:`isf.search.voxel_grid` and :mod:`isf.object._spanning_tree`.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..exceptions import InvalidInputError, ObjectLoadError
from ..search.voxel_grid import voxel_labels
from ._normals import estimate_normals, facing_away, orient_normals_mst, voxel_downsample
from ._readers import RawObject, read_source
from .mesh_sampling import (
    clean_mesh,
    orient_bodies,
    sample_by_area,
    triangle_normals,
    voxel_representatives,
)
from .surface import ObjectSurface

__all__ = ["UNIT_FACTORS", "load_object"]

logger = logging.getLogger(__name__)

UNIT_FACTORS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Length of one file unit in metres."""

TARGET_POINTS = 3000
"""Number of surface points the automatic voxel size aims for."""
_TARGET_BAND = (2500, 3500)
_KEEP_CLOUD_UP_TO = 4000
MIN_POINTS = 10
"""Fewest surface points an object may have."""
MAX_DIAGONAL = 2.0
"""Largest accepted bounding-box diagonal, metres."""
MIN_DIAGONAL = 0.002
"""Smallest accepted bounding-box diagonal, metres."""
K_NEIGHBOURS = 16
"""Neighbours (including the point itself) used for PCA normals and for orientation."""
_SAMPLES_PER_VOXEL = 12
_MAX_MESH_SAMPLES = 3_000_000


def load_object(
    source,
    *,
    scale: float = 1.0,
    units: str = "m",
    voxel_size: float | None = None,
    max_points: int | None = None,
    name: str | None = None,
    viewpoint=None,
) -> ObjectSurface:
    """Load a mesh or point cloud as surface points with outward normals.

    Args:
        source: a file path (STL, OBJ, PLY, OFF, GLB/GLTF, DAE, PCD, XYZ/TXT, NPY), an array
            of shape (N, 3) (points) or (N, 6) (points and normals), or a ``trimesh.Trimesh``
            / ``trimesh.Scene``.
        scale: extra factor applied to the coordinates (after ``units``).
        units: unit of the coordinates in ``source``: ``"m"``, ``"cm"`` or ``"mm"``.
        voxel_size: sampling resolution in metres; ``None`` picks it so the result has about
            3000 points (see the module docstring).
        max_points: upper bound on the number of points; the voxel size grows to meet it.
        name: label of the object; defaults to the file name, ``"array"`` or ``"mesh"``.
        viewpoint: optional camera position, shape (3,), metres, object frame (after
            scaling), for partial clouds and open scans: estimated cloud normals then face
            the camera (per connected part), as do given cloud normals and the normals of open
            mesh bodies (per point); watertight mesh bodies ignore it.

    Returns:
        The :class:`ObjectSurface` (points (N, 3) m, unit normals (N, 3), spacing m).

    Raises:
        ObjectLoadError: the source is missing, unreadable, empty, non-finite, too small,
            the wrong size for its units, or an array of the wrong shape.
        InvalidInputError: an argument (units, scale, voxel_size, max_points, viewpoint) is invalid.
    """
    factor = _unit_factor(units) * _positive_float(scale, "scale")
    if voxel_size is not None:
        voxel_size = _positive_float(voxel_size, "voxel_size")
    if max_points is not None and (
        isinstance(max_points, bool)
        or not isinstance(max_points, (int, np.integer))
        or max_points < MIN_POINTS
    ):
        raise InvalidInputError(
            f"max_points={max_points!r} is invalid: pass an integer >= {MIN_POINTS}"
        )
    view = _viewpoint(viewpoint)

    try:
        raw, default_name = read_source(source)
        label = name if name is not None else default_name
        if raw.faces is not None:
            surface = _mesh_surface(raw, factor, units, voxel_size, max_points, view, label)
        else:
            surface = _cloud_surface(raw, factor, units, voxel_size, max_points, view, label)
    except ObjectLoadError as exc:
        if exc.source is None and isinstance(source, (str, os.PathLike)):
            exc.source = Path(source)
        raise
    logger.info("loaded %s: %d points, spacing %.4g m", label, surface.n_points, surface.spacing)
    return surface


# --------------------------------------------------------------------------- arguments


def _unit_factor(units: str) -> float:
    """Metres per unit of ``units`` (a key of UNIT_FACTORS)."""
    try:
        return UNIT_FACTORS[units]
    except (KeyError, TypeError):
        raise InvalidInputError(
            f"units={units!r} is unknown: pass one of 'm', 'cm', 'mm'"
        ) from None


def _positive_float(value, what: str) -> float:
    """``value`` as a positive finite float; ``what`` names the argument in the error."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = float("nan")
    if not np.isfinite(out) or out <= 0.0:
        raise InvalidInputError(f"{what}={value!r} is invalid: pass a positive finite number")
    return out


def _viewpoint(viewpoint) -> np.ndarray | None:
    """The camera position as a finite (3,) float64 array, or None."""
    if viewpoint is None:
        return None
    try:
        view = np.asarray(viewpoint, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        view = np.full(3, np.nan)
    if not np.all(np.isfinite(view)):
        raise InvalidInputError(
            f"viewpoint={viewpoint!r} is invalid: pass a camera position (x, y, z) in metres"
        )
    return view


# --------------------------------------------------------------------------- validation


def _check_values(values: np.ndarray, what: str, label: str) -> None:
    """Reject an empty array or rows with NaN/inf; ``values`` (N, D), ``what`` names the rows."""
    if len(values) == 0:
        raise ObjectLoadError(
            f"{label} is empty (no {what}): pass a file that holds a mesh or point cloud"
        )
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ObjectLoadError(
            f"{label} has NaN or infinite values in {int(bad.sum())} {what} "
            f"(first at row {first}): remove those rows before loading"
        )


def _check_size(points: np.ndarray, units: str, label: str) -> None:
    """Reject objects whose bounding-box diagonal (metres) shows wrong units."""
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    unit_scale = UNIT_FACTORS[units]
    if diagonal > MAX_DIAGONAL:
        hint = next(
            (
                f"looks like {word}: pass units='{u}'"
                for u, word in (("mm", "millimetres"), ("cm", "centimetres"))
                if UNIT_FACTORS[u] < unit_scale
                and MIN_DIAGONAL <= diagonal * UNIT_FACTORS[u] / unit_scale <= MAX_DIAGONAL
            ),
            None,
        )
        hint = hint or "pass the right units= or a smaller scale="
        raise ObjectLoadError(
            f"{label} is {diagonal:.3g} m across (more than {MAX_DIAGONAL:g} m): {hint}"
        )
    if diagonal < MIN_DIAGONAL:
        hint = next(
            (
                f"looks like metres already: pass units='{u}'"
                for u in ("m", "cm")
                if UNIT_FACTORS[u] > unit_scale
                and MIN_DIAGONAL <= diagonal * UNIT_FACTORS[u] / unit_scale <= MAX_DIAGONAL
            ),
            None,
        )
        hint = hint or "pass a larger scale= (is the model normalised?)"
        raise ObjectLoadError(
            f"{label} is only {diagonal * 1000:.3g} mm across (less than "
            f"{MIN_DIAGONAL * 1000:g} mm): {hint}"
        )


def _check_count(n: int, label: str, voxel: float | None) -> None:
    """Reject fewer than MIN_POINTS points; ``voxel`` (m) is the size used, if any."""
    if n < MIN_POINTS:
        fix = f"pass a smaller voxel_size than {voxel:.3g} m" if voxel else "pass a denser cloud"
        raise ObjectLoadError(
            f"{label} has only {n} surface points (fewer than {MIN_POINTS}): {fix}"
        )


# --------------------------------------------------------------------------- resolution


def _voxelize(
    points: np.ndarray, size: float, auto: bool, max_points: int | None
) -> tuple[float, np.ndarray, int]:
    """Pick the voxel size and label the points with their voxels.

    With ``auto`` the size is refined from ``size`` (at most six times,
    ``h <- h * sqrt(n / target)``) until the occupied-voxel count lies in the target band; then
    it grows until the count is at most ``max_points``.

    Returns:
        (voxel size in metres, voxel label of every point (N,), number of occupied voxels).
    """
    target = TARGET_POINTS if max_points is None else min(TARGET_POINTS, max_points)
    low, high = min(_TARGET_BAND[0], 0.8 * target), min(_TARGET_BAND[1], target)
    labels, n = voxel_labels(points, size)
    for _ in range(6 if auto else 0):
        if low <= n <= high:
            break
        size *= float(np.clip(np.sqrt(n / target), 0.25, 4.0))
        labels, n = voxel_labels(points, size)
    while max_points is not None and n > max_points:
        size *= max(1.02, float(np.sqrt(n / max_points)))
        labels, n = voxel_labels(points, size)
    return size, labels, n


# --------------------------------------------------------------------------- surfaces


def _mesh_surface(
    raw: RawObject,
    factor: float,
    units: str,
    voxel_size: float | None,
    max_points: int | None,
    view: np.ndarray | None,
    label: str,
) -> ObjectSurface:
    """Clean, scale, orient and sample a mesh (file units, scaled by ``factor`` to metres)."""
    faces = np.asarray(raw.faces, dtype=np.int64)
    _check_values(np.asarray(raw.vertices), "vertices", label)
    vertices, faces = clean_mesh(np.asarray(raw.vertices, dtype=np.float64), faces)
    vertices = vertices * factor
    if len(faces) == 0:
        raise ObjectLoadError(f"{label} has no non-degenerate triangles: pass a valid mesh")
    _check_size(vertices, units, label)
    faces, closed = orient_bodies(vertices, faces)

    double_area, face_normals = triangle_normals(vertices, faces)
    area = 0.5 * double_area.sum()
    if not area > 0.0:
        raise ObjectLoadError(
            f"{label} has zero surface area: pass a mesh with non-degenerate triangles"
        )

    start = voxel_size if voxel_size is not None else np.sqrt(1.5 * area / TARGET_POINTS)
    n_samples = int(np.clip(_SAMPLES_PER_VOXEL * 1.5 * area / start**2, 20_000, _MAX_MESH_SAMPLES))
    if n_samples == _MAX_MESH_SAMPLES:
        logger.warning(
            "%s: voxel_size %.3g m needs more than %d samples; spacing will be uneven",
            label,
            start,
            _MAX_MESH_SAMPLES,
        )
    samples, tri = sample_by_area(vertices, faces, double_area, n_samples, seed=0)

    size, labels, n_vox = _voxelize(samples, start, voxel_size is None, max_points)
    pick = voxel_representatives(samples, labels, n_vox)
    points, normals = samples[pick], face_normals[tri[pick]]
    if view is not None:
        open_pick = ~closed[tri[pick]]
        normals[open_pick & facing_away(points, normals, view)] *= -1.0
    _check_count(len(points), label, size)
    return ObjectSurface(
        points=points,
        normals=normals,
        spacing=float(size),
        name=label,
        mesh_vertices=vertices,
        mesh_faces=faces,
    )


def _cloud_surface(
    raw: RawObject,
    factor: float,
    units: str,
    voxel_size: float | None,
    max_points: int | None,
    view: np.ndarray | None,
    label: str,
) -> ObjectSurface:
    """Scale, downsample and give normals to a cloud (file units, ``factor`` to metres)."""
    points = np.asarray(raw.points, dtype=np.float64)
    normals = raw.normals
    values = points if normals is None else np.hstack([points, normals])
    _check_values(values, "points", label)
    _check_count(len(points), label, None)
    points = points * factor
    _check_size(points, units, label)
    if normals is not None:
        length = np.linalg.norm(normals, axis=1)
        if (length < 1e-12).any():
            raise ObjectLoadError(
                f"{label} has {int((length < 1e-12).sum())} zero-length normals: fix them or "
                "pass only the x y z columns to have normals estimated"
            )
        normals = normals / length[:, None]

    size = voxel_size
    too_many = len(points) > (
        _KEEP_CLOUD_UP_TO if max_points is None else min(_KEEP_CLOUD_UP_TO, max_points)
    )
    if size is not None or too_many:
        start = size if size is not None else float(np.linalg.norm(np.ptp(points, axis=0))) / 50.0
        size, labels, n_vox = _voxelize(points, start, voxel_size is None, max_points)
        points, normals = voxel_downsample(points, normals, labels, n_vox)
    _check_count(len(points), label, size)

    tree = cKDTree(points)
    k = min(K_NEIGHBOURS, len(points))
    dist, neighbours = tree.query(points, k=k, workers=1)
    gaps = dist[:, 1][dist[:, 1] > 0]  # duplicated points have a zero gap
    spacing = float(size) if size is not None else float(np.median(gaps))
    if normals is None:
        normals = orient_normals_mst(points, estimate_normals(points, neighbours), neighbours, view)
    elif view is not None:
        normals[facing_away(points, normals, view)] *= -1.0
    return ObjectSurface(points=points, normals=normals, spacing=spacing, name=label)
