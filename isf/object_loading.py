"""Load an object mesh or point cloud into an :class:`~isf.object_surface.ObjectSurface`.

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
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from isf.exceptions import InvalidInputError, ObjectLoadError
from isf.object_surface import ObjectSurface

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
_MESH_SUFFIXES = {".stl", ".obj", ".off", ".glb", ".gltf", ".ply", ".dae"}
_XYZ_SUFFIXES = {".xyz", ".xyzn", ".txt"}


@dataclass
class _RawObject:
    """What a reader found, in file units: a cloud (points, normals) or a mesh (vertices, faces)."""

    points: np.ndarray | None = None
    normals: np.ndarray | None = None
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None


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

    raw, default_name = _read_source(source)
    label = name if name is not None else default_name
    if raw.faces is not None:
        surface = _mesh_surface(raw, factor, units, voxel_size, max_points, view, label)
    else:
        surface = _cloud_surface(raw, factor, units, voxel_size, max_points, view, label)
    logger.info("loaded %s: %d points, spacing %.4g m", label, surface.n_points, surface.spacing)
    return surface


# --------------------------------------------------------------------------- arguments


def _unit_factor(units: str) -> float:
    try:
        return UNIT_FACTORS[units]
    except (KeyError, TypeError):
        raise InvalidInputError(
            f"units={units!r} is unknown: pass one of 'm', 'cm', 'mm'"
        ) from None


def _positive_float(value, what: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = float("nan")
    if not np.isfinite(out) or out <= 0.0:
        raise InvalidInputError(f"{what}={value!r} is invalid: pass a positive finite number")
    return out


def _viewpoint(viewpoint) -> np.ndarray | None:
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


# --------------------------------------------------------------------------- readers


def _read_source(source) -> tuple[_RawObject, str]:
    """Dispatch on the kind of ``source``; return the raw data (file units) and a default name."""
    if isinstance(source, np.ndarray):
        return _raw_from_array(source, "array"), "array"
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        return _read_file(path), path.name
    import trimesh  # imported here: it takes ~0.7 s and clouds do not need it

    if isinstance(source, (trimesh.Trimesh, trimesh.Scene)):
        return _raw_from_geometry(source, "the mesh"), "mesh"
    raise ObjectLoadError(
        f"cannot load an object from {type(source).__name__}: pass a file path, an (N, 3)/(N, 6) "
        "array or a trimesh.Trimesh"
    )


def _read_file(path: Path) -> _RawObject:
    if not path.exists():
        raise ObjectLoadError(f"object file {path} does not exist: check the path")
    if not path.is_file():
        raise ObjectLoadError(f"object path {path} is not a file: pass a mesh or point-cloud file")
    if path.stat().st_size == 0:
        raise ObjectLoadError(
            f"object file {path} is empty: pass a file that holds a mesh or point cloud"
        )
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            array = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise ObjectLoadError(
                f"cannot read {path} as NumPy .npy ({exc}): save it with numpy.save"
            ) from exc
        return _raw_from_array(array, str(path))
    if suffix in _XYZ_SUFFIXES:
        return _raw_from_array(_read_xyz(path), str(path))
    if suffix == ".pcd":
        return _read_pcd(path)
    if suffix == ".obj":
        return _read_obj(path)
    if suffix in _MESH_SUFFIXES:
        return _read_with_trimesh(path)
    raise ObjectLoadError(
        f"unknown object format {suffix or '(no suffix)'!r} of {path}: "
        "use STL, OBJ, PLY, OFF, GLB, PCD, XYZ or NPY"
    )


def _read_xyz(path: Path) -> np.ndarray:
    """Read "x y z" or "x y z nx ny nz" lines (whitespace or commas; '#' comments)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ObjectLoadError(
            f"cannot read {path} as XYZ text ({exc}): write 'x y z [nx ny nz]' lines"
        ) from exc
    rows = [line.split("#", 1)[0].replace(",", " ") for line in text.splitlines()]
    rows = [line for line in rows if line.strip()]
    if not rows:
        raise ObjectLoadError(
            f"object file {path} holds no points: write one 'x y z [nx ny nz]' line per point"
        )
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.loadtxt(rows, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise ObjectLoadError(
            f"cannot read {path} as XYZ text ({exc}): write 'x y z [nx ny nz]' lines"
        ) from exc


def _read_obj(path: Path) -> _RawObject:
    """Read the ``v`` and ``f`` lines of a Wavefront OBJ (polygons fan-triangulated).

    Texture and normal indices (``f v/vt/vn``), materials and groups are ignored; OBJ has no
    transforms, so every object of the file is kept as it is.
    """
    try:
        text = "\n" + path.read_text(errors="replace").replace("\r", "").replace("\t", " ")
        vertex_rows = [chunk.partition("\n")[0] for chunk in text.split("\nv ")[1:]]
        face_rows = [chunk.partition("\n")[0] for chunk in text.split("\nf ")[1:]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # loadtxt warns on empty input
            vertices = np.loadtxt(vertex_rows, dtype=np.float64, usecols=(0, 1, 2), ndmin=2)
            index, sizes = _obj_triangles(face_rows)
    except (OSError, ValueError, IndexError) as exc:
        raise ObjectLoadError(
            f"cannot read {path} as OBJ ({exc}): check that the file is a valid mesh"
        ) from exc
    if len(index) == 0:
        if len(vertices) == 0:
            raise ObjectLoadError(
                f"no vertices could be read from {path}: the file is not an OBJ mesh"
            )
        return _RawObject(points=vertices)
    if sizes.min() < 3 or (index == 0).any():
        raise ObjectLoadError(
            f"{path} has faces with fewer than 3 vertices or index 0 (OBJ counts from 1): "
            "repair or re-export the mesh"
        )
    if (index < 0).any():
        # Negative indices count back from the vertices read before the face's line.
        kinds = [line[:2] for line in text.split("\n") if line[:2] in ("v ", "f ")]
        is_vertex = np.array([k == "v " for k in kinds], dtype=bool)
        base = np.repeat(np.cumsum(is_vertex)[~is_vertex], sizes - 2)[:, None]
        return _RawObject(vertices=vertices, faces=np.where(index > 0, index - 1, base + index))
    return _RawObject(vertices=vertices, faces=index - 1)


def _obj_triangles(face_rows: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Vertex indices (as written, 1-based or negative) of OBJ face rows, fan-triangulated.

    Returns:
        (triangles (T, 3) int64, polygon sizes (F,) int64).
    """
    if not face_rows:
        return np.empty((0, 3), dtype=np.int64), np.empty(0, dtype=np.int64)
    # Fast path: every row a triangle with the same "v/vt/vn" layout as the first token.
    first = face_rows[0].split()
    stride = len(first[0].replace("//", " ").replace("/", " ").split()) if first else 1
    flat = "\n".join(face_rows).replace("//", " ").replace("/", " ").split("\n")
    try:
        table = np.loadtxt(flat, dtype=np.int64, ndmin=2)
        if table.shape[1] == 3 * stride:
            return table[:, ::stride], np.full(len(table), 3, dtype=np.int64)
    except ValueError:
        pass
    polygons = [[int(token.split("/", 1)[0]) for token in row.split()] for row in face_rows]
    sizes = np.array([len(p) for p in polygons], dtype=np.int64)
    tris = [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)]
    return np.array(tris, dtype=np.int64).reshape(-1, 3), sizes


_PCD_TYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}


def _read_pcd(path: Path) -> _RawObject:
    """Read a PCL .pcd file (DATA ascii or binary); x y z and normal_x/y/z (or nx/ny/nz)."""
    data = path.read_bytes()
    header: dict[str, list[str]] = {}
    offset = 0
    while offset < len(data):
        end = data.find(b"\n", offset)
        end = len(data) if end < 0 else end
        line = data[offset:end].decode("ascii", "replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    if "DATA" not in header or "FIELDS" not in header:
        raise ObjectLoadError(
            f"cannot read {path} as PCD (no FIELDS/DATA header): save it with PCL or Open3D"
        )
    fields = header["FIELDS"]
    counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    n = (
        int(header.get("POINTS", [0])[0])
        if "POINTS" in header
        else (int(header.get("WIDTH", ["0"])[0]) * int(header.get("HEIGHT", ["1"])[0]))
    )
    try:
        if mode == "ascii":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                table = np.loadtxt(
                    data[offset:].decode("ascii").splitlines(), dtype=np.float64, ndmin=2
                )
            columns = np.cumsum([0] + counts)
            cols = {f: table[:, columns[i]] for i, f in enumerate(fields)}
        elif mode == "binary":
            sizes = [int(s) for s in header["SIZE"]]
            types = [t.upper() for t in header["TYPE"]]
            dtype = np.dtype(
                [
                    (f"f{i}", _PCD_TYPES[(t, s)], (c,))
                    for i, (t, s, c) in enumerate(zip(types, sizes, counts))
                ]
            )
            records = np.frombuffer(data, dtype=dtype, count=n, offset=offset)
            cols = {f: records[f"f{i}"][:, 0].astype(np.float64) for i, f in enumerate(fields)}
        elif mode == "binary_compressed":
            raise ObjectLoadError(
                f"{path} is a binary_compressed PCD, which isf does not read: re-save it as "
                "ascii or binary (pcl_convert_pcd_ascii_binary, or Open3D write_point_cloud "
                "with compressed=False)"
            )
        else:
            raise ObjectLoadError(
                f"cannot read {path}: unknown PCD DATA mode {mode!r}; use ascii or binary"
            )
    except (ValueError, KeyError, IndexError) as exc:
        raise ObjectLoadError(
            f"cannot read {path} as PCD ({exc}): the file is corrupt or truncated"
        ) from exc
    if not {"x", "y", "z"} <= set(cols):
        raise ObjectLoadError(
            f"{path} has no x y z fields (fields: {' '.join(fields)}): save the points' xyz"
        )
    points = np.column_stack([cols["x"], cols["y"], cols["z"]])
    normal_names = next(
        (
            names
            for names in (("normal_x", "normal_y", "normal_z"), ("nx", "ny", "nz"))
            if set(names) <= set(cols)
        ),
        None,
    )
    normals = None if normal_names is None else np.column_stack([cols[c] for c in normal_names])
    # PCL marks invalid points (e.g. missing pixels of organised clouds) with NaN coordinates.
    valid = ~np.isnan(points).all(axis=1)
    if not valid.all():
        logger.info("%s: dropped %d invalid (NaN) PCD points", path, int((~valid).sum()))
        points = points[valid]
        normals = None if normals is None else normals[valid]
    array = points if normals is None else np.hstack([points, normals])
    return _raw_from_array(array, str(path))


def _read_with_trimesh(path: Path) -> _RawObject:
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, skip_materials=True)
    except Exception as exc:
        raise ObjectLoadError(
            f"cannot read {path} as {path.suffix[1:].upper()} ({type(exc).__name__}: {exc}): "
            "check that the file is a valid mesh"
        ) from exc
    return _raw_from_geometry(loaded, str(path))


def _raw_from_geometry(geometry, where: str) -> _RawObject:
    """Collect the triangles of a Trimesh/Scene (with scene transforms), else its points."""
    import trimesh

    if isinstance(geometry, trimesh.Scene):
        parts = []
        for node in geometry.graph.nodes_geometry:
            transform, geom_name = geometry.graph[node]
            geom = geometry.geometry.get(geom_name)
            if geom is not None:
                parts.append((np.asarray(transform, dtype=np.float64), geom))
    else:
        parts = [(np.eye(4), geometry)]

    vertices, faces, clouds, offset = [], [], [], 0
    for transform, geom in parts:
        points = np.asarray(getattr(geom, "vertices", np.empty((0, 3))), dtype=np.float64).reshape(
            -1, 3
        )
        points = points @ transform[:3, :3].T + transform[:3, 3]
        tris = getattr(geom, "faces", None)
        if isinstance(geom, trimesh.Trimesh) and tris is not None and len(tris):
            vertices.append(points)
            faces.append(np.asarray(tris, dtype=np.int64) + offset)
            offset += len(points)
        elif isinstance(geom, (trimesh.PointCloud, trimesh.Trimesh)) and len(points):
            clouds.append((points, _ply_normals(geom)))  # a vertex-only geometry is a cloud
    if faces:
        return _RawObject(vertices=np.vstack(vertices), faces=np.vstack(faces))
    if clouds:
        points = np.vstack([c[0] for c in clouds])
        normals = None
        if all(c[1] is not None for c in clouds):
            normals = np.vstack([c[1] for c in clouds])
        return _raw_from_array(points if normals is None else np.hstack([points, normals]), where)
    raise ObjectLoadError(
        f"no triangles or points could be read from {where}: the file is corrupt, empty or not a "
        "mesh/point cloud"
    )


def _ply_normals(cloud) -> np.ndarray | None:
    """Per-vertex normals of a PLY point cloud, read from trimesh's raw PLY metadata."""
    raw = cloud.metadata.get("_ply_raw", {}).get("vertex", {}).get("data")
    if raw is None:
        return None
    names = raw.dtype.names if hasattr(raw, "dtype") else tuple(raw)
    if names is None or not {"nx", "ny", "nz"} <= set(names):
        return None
    return np.column_stack(
        [np.asarray(raw[c], dtype=np.float64).reshape(-1) for c in ("nx", "ny", "nz")]
    )


def _raw_from_array(array, where: str) -> _RawObject:
    array = np.asarray(array)
    if array.ndim != 2 or array.shape[1] not in (3, 6) or not np.issubdtype(array.dtype, np.number):
        raise ObjectLoadError(
            f"{where} has shape {array.shape} and dtype {array.dtype}: pass numbers shaped (N, 3) "
            "(points) or (N, 6) (points and normals)"
        )
    array = array.astype(np.float64)
    if array.shape[1] == 6:
        return _RawObject(points=array[:, :3], normals=array[:, 3:])
    return _RawObject(points=array)


# --------------------------------------------------------------------------- validation


def _check_values(values: np.ndarray, what: str, label: str) -> None:
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
    if n < MIN_POINTS:
        fix = f"pass a smaller voxel_size than {voxel:.3g} m" if voxel else "pass a denser cloud"
        raise ObjectLoadError(
            f"{label} has only {n} surface points (fewer than {MIN_POINTS}): {fix}"
        )


# --------------------------------------------------------------------------- voxels


def _voxel_labels(points: np.ndarray, size: float) -> tuple[np.ndarray, int]:
    """Label each point with its voxel of the grid ``floor(p / size)``.

    Returns:
        (voxel label of every point (N,), number of occupied voxels).
    """
    ijk = np.floor(points / size).astype(np.int64)
    ijk -= ijk.min(axis=0)
    dims = ijk.max(axis=0) + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) > 2.0**62:
        raise InvalidInputError(
            f"voxel_size={size:.3g} m is too small for this object: pass a larger voxel_size"
        )
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, labels = np.unique(keys, return_inverse=True)
    return labels.reshape(-1), int(labels.max()) + 1


def _group_mean(values: np.ndarray, labels: np.ndarray, n_groups: int) -> np.ndarray:
    counts = np.bincount(labels, minlength=n_groups).astype(np.float64)
    sums = np.stack(
        [
            np.bincount(labels, weights=values[:, d], minlength=n_groups)
            for d in range(values.shape[1])
        ],
        axis=1,
    )
    return sums / counts[:, None]


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
    labels, n = _voxel_labels(points, size)
    for _ in range(6 if auto else 0):
        if low <= n <= high:
            break
        size *= float(np.clip(np.sqrt(n / target), 0.25, 4.0))
        labels, n = _voxel_labels(points, size)
    while max_points is not None and n > max_points:
        size *= max(1.02, float(np.sqrt(n / max_points)))
        labels, n = _voxel_labels(points, size)
    return size, labels, n


# --------------------------------------------------------------------------- spanning-tree signs


def _tree_signs(
    n: int, edges: np.ndarray, weights: np.ndarray, seeds_of: Callable, flip_of: Callable
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate a sign (+1/-1) per node along a minimum spanning forest.

    Args:
        n: number of nodes.
        edges: undirected edges, shape (E, 2).
        weights: positive edge weights, shape (E,).
        seeds_of: ``labels (n,) -> seeds (C,)``, one node per connected component.
        flip_of: ``(children (M,), parents (M,)) -> bool (M,)``, True where the child's sign must
            be the opposite of its parent's.

    Returns:
        (signs (n,) int8 with +1 at every seed, component labels (n,)).
    """
    i, j = np.minimum(edges[:, 0], edges[:, 1]), np.maximum(edges[:, 0], edges[:, 1])
    keep = i != j
    key, first = np.unique(i[keep] * n + j[keep], return_index=True)
    w = weights[keep][first]
    graph = coo_matrix((w, (key // n, key % n)), shape=(n, n)).tocsr()
    n_comp, labels = connected_components(graph, directed=False)
    seeds = np.asarray(seeds_of(labels), dtype=np.int64)
    tree = minimum_spanning_tree(graph).tocoo()
    # A virtual root (node n) joined to every seed turns the forest into one tree.
    rows = np.concatenate([tree.row, np.full(n_comp, n)])
    cols = np.concatenate([tree.col, seeds])
    forest = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    order, parent = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    order = order[1:]
    parent = parent[:n].copy()
    parent[seeds] = -1
    nonseed = order[parent[order] >= 0]
    flips = np.zeros(n, dtype=bool)
    flips[nonseed] = flip_of(nonseed, parent[nonseed])
    sign = [1] * n
    par, flp = parent.tolist(), flips.tolist()
    for v in order.tolist():
        p = par[v]
        if p >= 0:
            sign[v] = -sign[p] if flp[v] else sign[p]
    return np.asarray(sign, dtype=np.int8), labels


# --------------------------------------------------------------------------- meshes


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group equal rows of a 2-D array.

    Returns:
        (one member index per group (G,), group of every row (N,)).
    """
    order = np.lexsort(rows.T[::-1])
    ranked = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = (ranked[1:] != ranked[:-1]).any(axis=1)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def _clean_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices by position (ignores UV/normal seams); drop collapsed, repeated triangles
    and unreferenced vertices."""
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ObjectLoadError(
            "the mesh has face indices outside its vertex list: repair or re-export the mesh"
        )
    rounded = np.round(vertices, 8) + 0.0  # + 0.0 turns -0.0 into 0.0 so both merge
    first, inverse = _unique_rows(rounded)
    faces = inverse[faces]
    faces = faces[
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    ]
    if len(faces) == 0:
        return vertices[:0], faces
    kept, _ = _unique_rows(np.sort(faces, axis=1))
    faces = faces[np.sort(kept)]
    used = np.flatnonzero(np.bincount(faces.reshape(-1), minlength=len(first)))
    remap = np.zeros(len(first), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[first[used]], remap[faces]


def _orient_bodies(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Give each watertight body a consistent winding with positive volume; keep open bodies.

    Returns:
        (faces (F, 3) reoriented, closed (F,) bool: True where the face's body is watertight).
    """
    n_faces = len(faces)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)  # (3F, 2)
    keys = directed.min(axis=1) * len(vertices) + directed.max(axis=1)
    order = np.argsort(keys)
    ranked = keys[order]
    group = np.cumsum(np.r_[True, ranked[1:] != ranked[:-1]]) - 1
    ranked_count = np.bincount(group)[group]
    edge_count = np.empty(len(keys), dtype=np.int64)
    edge_count[order] = ranked_count
    # Adjacency over manifold edges (shared by exactly two triangles).
    shared = ranked_count == 2
    pairs = (order[shared] // 3).reshape(-1, 2)
    pair_starts = directed[order[shared], 0].reshape(-1, 2)

    if (pair_starts[:, 0] != pair_starts[:, 1]).all():  # winding already consistent
        graph = coo_matrix(
            (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_faces, n_faces)
        )
        body = connected_components(graph, directed=False)[1]
        sign = np.ones(n_faces, dtype=np.int8)
    else:

        def flip_of(child: np.ndarray, parent: np.ndarray) -> np.ndarray:
            # The same directed edge in both triangles means opposite windings.
            a = np.stack([faces[child], np.roll(faces[child], -1, axis=1)], axis=2)
            b = np.stack([faces[parent], np.roll(faces[parent], -1, axis=1)], axis=2)
            return (a[:, :, None, :] == b[:, None, :, :]).all(axis=3).any(axis=(1, 2))

        def first_face(labels: np.ndarray) -> np.ndarray:
            return np.unique(labels, return_index=True)[1]

        sign, body = _tree_signs(n_faces, pairs, np.ones(len(pairs)), first_face, flip_of)
    closed_edge = edge_count.reshape(-1, 3) == 2
    n_body = int(body.max()) + 1
    closed = (
        np.bincount(body, weights=(~closed_edge.all(axis=1)).astype(np.float64), minlength=n_body)
        == 0
    )
    closed_face = closed[body]
    faces = faces.copy()
    flip = closed_face & (sign < 0)
    faces[flip] = faces[flip][:, ::-1]
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    volume = np.bincount(
        body, weights=np.einsum("ij,ij->i", v0, np.cross(v1, v2)), minlength=n_body
    )
    inverted = closed_face & (volume[body] < 0)
    faces[inverted] = faces[inverted][:, ::-1]
    logger.debug(
        "mesh: %d bodies, %d watertight, %d faces flipped",
        n_body,
        int(closed.sum()),
        int((flip ^ inverted).sum()),
    )
    return faces, closed_face


def _mesh_surface(
    raw: _RawObject,
    factor: float,
    units: str,
    voxel_size: float | None,
    max_points: int | None,
    view: np.ndarray | None,
    label: str,
) -> ObjectSurface:
    faces = np.asarray(raw.faces, dtype=np.int64)
    _check_values(np.asarray(raw.vertices), "vertices", label)
    vertices, faces = _clean_mesh(np.asarray(raw.vertices, dtype=np.float64), faces)
    vertices = vertices * factor
    if len(faces) == 0:
        raise ObjectLoadError(f"{label} has no non-degenerate triangles: pass a valid mesh")
    _check_size(vertices, units, label)
    faces, closed = _orient_bodies(vertices, faces)

    cross = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    double_area = np.linalg.norm(cross, axis=1)
    area = 0.5 * double_area.sum()
    if not area > 0.0:
        raise ObjectLoadError(
            f"{label} has zero surface area: pass a mesh with non-degenerate triangles"
        )
    face_normals = cross / np.where(double_area > 0, double_area, 1.0)[:, None]

    start = voxel_size if voxel_size is not None else np.sqrt(1.5 * area / TARGET_POINTS)
    n_samples = int(np.clip(_SAMPLES_PER_VOXEL * 1.5 * area / start**2, 20_000, _MAX_MESH_SAMPLES))
    if n_samples == _MAX_MESH_SAMPLES:
        logger.warning(
            "%s: voxel_size %.3g m needs more than %d samples; spacing will be uneven",
            label,
            start,
            _MAX_MESH_SAMPLES,
        )
    rng = np.random.default_rng(0)
    tri = rng.choice(len(faces), size=n_samples, p=double_area / double_area.sum())
    r1, r2 = np.sqrt(rng.random(n_samples)), rng.random(n_samples)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    samples = np.einsum("nk,nkd->nd", bary, vertices[faces[tri]])

    size, labels, n_vox = _voxelize(samples, start, voxel_size is None, max_points)
    # Keep, in every voxel, the sample nearest the mean of the voxel's samples.
    centre = _group_mean(samples, labels, n_vox)
    dist2 = np.einsum("ij,ij->i", samples - centre[labels], samples - centre[labels])
    best = np.full(n_vox, np.inf)
    np.minimum.at(best, labels, dist2)
    candidates = np.flatnonzero(dist2 == best[labels])
    _, first = np.unique(labels[candidates], return_index=True)
    pick = candidates[first]
    points, normals = samples[pick], face_normals[tri[pick]]
    if view is not None:
        open_pick = ~closed[tri[pick]]
        away = np.einsum("ij,ij->i", normals, view - points) < 0
        normals[open_pick & away] *= -1.0
    _check_count(len(points), label, size)
    return ObjectSurface(
        points=points,
        normals=normals,
        spacing=float(size),
        name=label,
        mesh_vertices=vertices,
        mesh_faces=faces,
    )


# --------------------------------------------------------------------------- point clouds


def _estimate_normals(points: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Unoriented unit normals: least-variance direction of each point's k-NN (PCA)."""
    local = points[neighbours]
    local = local - local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    _, vectors = np.linalg.eigh(cov)
    return vectors[:, :, 0]


def _orient_normals_mst(
    points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray, view: np.ndarray | None = None
) -> np.ndarray:
    """Turn unoriented normals to one consistent, outward side.

    Signs propagate along a minimum spanning tree of the k-NN graph (weight ``1 - |n_i . n_j|``)
    from one seed per connected part: the point farthest from the part's centroid. Each part then
    faces outward: without ``view`` the seed's normal points away from the part's centroid; with
    ``view`` (camera position, (3,)) the part is flipped when most normals face away from the
    camera (a vote weighted by ``cos`` of the viewing angle).

    Args:
        points: (N, 3) metres. normals: (N, 3) unit. neighbours: (N, k) k-NN indices.

    Returns:
        Oriented unit normals, shape (N, 3).
    """
    n = len(points)
    edges = np.stack([np.repeat(np.arange(n), neighbours.shape[1]), neighbours.reshape(-1)], axis=1)
    cos = np.abs(np.einsum("ij,ij->i", normals[edges[:, 0]], normals[edges[:, 1]]))
    weights = 1.0 - cos + 1e-6  # scipy graphs drop zero-weight edges

    def farthest(labels: np.ndarray) -> np.ndarray:
        centre = _group_mean(points, labels, int(labels.max()) + 1)
        d2 = np.einsum("ij,ij->i", points - centre[labels], points - centre[labels])
        order = np.lexsort((-d2, labels))
        return order[np.r_[0, np.flatnonzero(np.diff(labels[order])) + 1]]

    def flip_of(child: np.ndarray, parent: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", normals[child], normals[parent]) < 0

    sign, labels = _tree_signs(n, edges, weights, farthest, flip_of)
    oriented = normals * sign[:, None]
    n_parts = int(labels.max()) + 1
    if view is None:
        seeds = farthest(labels)
        centre = _group_mean(points, labels, n_parts)
        outward = np.einsum("ij,ij->i", oriented[seeds], points[seeds] - centre[labels[seeds]])
        vote = np.zeros(n_parts)
        vote[labels[seeds]] = outward
    else:
        sight = view - points
        sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-12)
        vote = np.bincount(
            labels, weights=np.einsum("ij,ij->i", oriented, sight), minlength=n_parts
        )
    oriented[(vote < 0)[labels]] *= -1.0
    return oriented


def _cloud_surface(
    raw: _RawObject,
    factor: float,
    units: str,
    voxel_size: float | None,
    max_points: int | None,
    view: np.ndarray | None,
    label: str,
) -> ObjectSurface:
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
        points = _group_mean(points, labels, n_vox)
        if normals is not None:
            mean = _group_mean(normals, labels, n_vox)
            length = np.linalg.norm(mean, axis=1)
            # Opposite normals in one voxel (a thin wall) cancel: keep one member's normal there.
            _, member = np.unique(labels, return_index=True)
            mean[length < 1e-6] = normals[member[length < 1e-6]]
            normals = mean / np.linalg.norm(mean, axis=1, keepdims=True)
    _check_count(len(points), label, size)

    tree = cKDTree(points)
    k = min(K_NEIGHBOURS, len(points))
    dist, neighbours = tree.query(points, k=k, workers=1)
    gaps = dist[:, 1][dist[:, 1] > 0]  # duplicated points have a zero gap
    spacing = float(size) if size is not None else float(np.median(gaps))
    if normals is None:
        normals = _orient_normals_mst(
            points, _estimate_normals(points, neighbours), neighbours, view
        )
    elif view is not None:
        away = np.einsum("ij,ij->i", normals, view - points) < 0
        normals[away] *= -1.0
    return ObjectSurface(points=points, normals=normals, spacing=spacing, name=label)
