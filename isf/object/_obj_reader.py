"""Read Wavefront OBJ meshes: ``v`` and ``f`` lines, polygons fan-triangulated.

Texture and normal indices (``f v/vt/vn``), materials, groups and ``vt``/``vn`` lines are
ignored. Faces may use 1-based or negative (relative) indices, with or without slashes.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..exceptions import ObjectLoadError

__all__ = ["read_obj"]


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Read the ``v`` and ``f`` lines of a Wavefront OBJ (polygons fan-triangulated).

    Texture and normal indices (``f v/vt/vn``), materials and groups are ignored; OBJ has no
    transforms, so every object of the file is kept as it is.

    Args:
        path: the ``.obj`` file.

    Returns:
        (vertices (V, 3) float64 in file units, faces (F, 3) int64 0-based indices into
        ``vertices``), or (vertices, None) when the file has vertices but no faces.

    Raises:
        ObjectLoadError: the file cannot be parsed, has no vertices, or has faces with fewer
            than 3 vertices, index 0 or an index past the vertices.
    """
    try:
        text = "\n" + path.read_text(errors="replace").replace("\r", "").replace("\t", " ")
        vertex_rows = [chunk.partition("\n")[0] for chunk in text.split("\nv ")[1:]]
        face_rows = [chunk.partition("\n")[0] for chunk in text.split("\nf ")[1:]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # loadtxt warns on empty input
            vertices = np.loadtxt(vertex_rows, dtype=np.float64, usecols=(0, 1, 2), ndmin=2)
            index, sizes = _obj_triangles(face_rows)
    except (OSError, ValueError, IndexError, OverflowError) as exc:
        raise ObjectLoadError(
            f"cannot read {path} as OBJ ({exc}): check that the file is a valid mesh"
        ) from exc
    if len(index) == 0:
        if len(vertices) == 0:
            raise ObjectLoadError(
                f"no vertices could be read from {path}: the file is not an OBJ mesh"
            )
        return vertices, None
    if sizes.min() < 3 or (index == 0).any():
        raise ObjectLoadError(
            f"{path} has faces with fewer than 3 vertices or index 0 (OBJ counts from 1): "
            "repair or re-export the mesh"
        )
    if (index > len(vertices)).any() or (index < -len(vertices)).any():
        raise ObjectLoadError(
            f"{path} has faces that name vertices it does not have (indices up to "
            f"{int(np.abs(index).max())} for {len(vertices)} vertices): repair or re-export the mesh"
        )
    if (index < 0).any():
        # Negative indices count back from the vertices read before the face's line.
        kinds = [line[:2] for line in text.split("\n") if line[:2] in ("v ", "f ")]
        is_vertex = np.array([k == "v " for k in kinds], dtype=bool)
        base = np.repeat(np.cumsum(is_vertex)[~is_vertex], sizes - 2)[:, None]
        return vertices, np.where(index > 0, index - 1, base + index)
    return vertices, index - 1


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

