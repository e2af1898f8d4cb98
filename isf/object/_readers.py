"""Read an object source into raw data in file units: a mesh or a point cloud.

Sources: a file path (STL, OBJ, PLY, OFF, GLB/GLTF, DAE, PCD, XYZ/XYZN/TXT, NPY), an array of
shape (N, 3) (points) or (N, 6) (points and normals), or a ``trimesh.Trimesh`` /
``trimesh.Scene``. Scene geometries are placed with their scene transforms. Nothing is scaled,
cleaned or checked for size here; :mod:`isf.object.loading` does that.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import ObjectLoadError
from ._obj_reader import read_obj
from ._pcd_reader import read_pcd

__all__ = ["RawObject", "check_file", "read_source"]

_MESH_SUFFIXES = {".stl", ".obj", ".off", ".glb", ".gltf", ".ply", ".dae"}
_XYZ_SUFFIXES = {".xyz", ".xyzn", ".txt"}


@dataclass
class RawObject:
    """What a reader found, in file units: a cloud (points, normals) or a mesh (vertices, faces).

    Attributes:
        points: cloud points (N, 3), or None for a mesh.
        normals: cloud normals (N, 3) as given (not normalised), or None.
        vertices: mesh vertices (V, 3), or None for a cloud.
        faces: mesh triangles (F, 3), 0-based indices into ``vertices``, or None for a cloud.
    """

    points: np.ndarray | None = None
    normals: np.ndarray | None = None
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None


def read_source(source) -> tuple[RawObject, str]:
    """Dispatch on the kind of ``source``; return the raw data (file units) and a default name.

    Args:
        source: a file path, an (N, 3)/(N, 6) array, or a ``trimesh.Trimesh``/``Scene``.

    Returns:
        (raw data in file units, default name: the file name, ``"array"`` or ``"mesh"``).

    Raises:
        ObjectLoadError: the source is of an unknown type, missing, empty, unreadable, of an
            unknown format, or an array of the wrong shape.
    """
    if isinstance(source, np.ndarray):
        return _raw_from_array(source, "array"), "array"
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        return _read_file(path), path.name
    import trimesh  # imported here: importing it is slow and clouds do not need it

    if isinstance(source, (trimesh.Trimesh, trimesh.Scene)):
        return _raw_from_geometry(source, "the mesh"), "mesh"
    raise ObjectLoadError(
        f"cannot load an object from {type(source).__name__}: pass a file path, an (N, 3)/(N, 6) "
        "array or a trimesh.Trimesh"
    )


def check_file(path: Path) -> None:
    """Check, without reading it, that ``path`` is a non-empty file of a format isf reads.

    Raises:
        ObjectLoadError: a missing path, a folder, an empty file or an unknown suffix.
    """
    if not path.exists():
        raise ObjectLoadError(f"object file {path} does not exist: check the path")
    if not path.is_file():
        raise ObjectLoadError(f"object path {path} is not a file: pass a mesh or point-cloud file")
    if path.stat().st_size == 0:
        raise ObjectLoadError(
            f"object file {path} is empty: pass a file that holds a mesh or point cloud"
        )
    suffix = path.suffix.lower()
    if suffix not in {".npy", ".pcd", ".obj", *_XYZ_SUFFIXES, *_MESH_SUFFIXES}:
        raise ObjectLoadError(
            f"unknown object format {suffix or '(no suffix)'!r} of {path}: "
            "use STL, OBJ, PLY, OFF, GLB, PCD, XYZ or NPY"
        )


def _read_file(path: Path) -> RawObject:
    """Check ``path`` (:func:`check_file`) and read it by its suffix."""
    check_file(path)
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
        return _raw_from_array(read_pcd(path), str(path))
    if suffix == ".obj":
        vertices, faces = read_obj(path)
        if faces is None:
            return RawObject(points=vertices)
        return RawObject(vertices=vertices, faces=faces)
    return _read_with_trimesh(path)  # one of _MESH_SUFFIXES (check_file)


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



def _read_with_trimesh(path: Path) -> RawObject:
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, skip_materials=True)
    except Exception as exc:
        raise ObjectLoadError(
            f"cannot read {path} as {path.suffix[1:].upper()} ({type(exc).__name__}: {exc}): "
            "check that the file is a valid mesh"
        ) from exc
    return _raw_from_geometry(loaded, str(path))


def _raw_from_geometry(geometry, where: str) -> RawObject:
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
        return RawObject(vertices=np.vstack(vertices), faces=np.vstack(faces))
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


def _raw_from_array(array, where: str) -> RawObject:
    """Split numbers shaped (N, 3) (points) or (N, 6) (points, normals) into a float64 cloud."""
    array = np.asarray(array)
    if array.ndim != 2 or array.shape[1] not in (3, 6) or not np.issubdtype(array.dtype, np.number):
        raise ObjectLoadError(
            f"{where} has shape {array.shape} and dtype {array.dtype}: pass numbers shaped (N, 3) "
            "(points) or (N, 6) (points and normals)"
        )
    array = array.astype(np.float64)
    if array.shape[1] == 6:
        return RawObject(points=array[:, :3], normals=array[:, 3:])
    return RawObject(points=array)

