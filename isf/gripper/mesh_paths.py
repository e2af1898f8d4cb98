"""Resolve the mesh filenames written in a URDF to files on disk.

A URDF names meshes in four ways; each is tried in this order:

``file:///abs/path.stl`` or ``/abs/path.stl``
    Used as is.
``package://pkg/rest``
    1. ``package_dirs[pkg] / rest`` (the explicit package map wins);
    2. the URDF's folder and each of its parents ``P``: ``P / rest`` when ``P`` is
       named ``pkg``, and ``P / pkg / rest`` when ``P`` holds a folder ``pkg``;
    3. ``rest`` and then ``pkg / rest`` relative to the URDF's folder (vendor files
       such as the Franka hand write ``package://meshes/...`` for a folder beside them).
anything else
    Relative to the URDF's folder.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from urllib.parse import unquote, urlparse

from ..exceptions import MeshNotFoundError

__all__ = ["MeshNotFoundError", "mesh_path_candidates", "resolve_mesh_path"]

PackageDirs = Mapping[str, "str | Path"]


def _package_candidates(
    pkg: str, rest: str, urdf_dir: Path, package_dirs: PackageDirs
) -> list[Path]:
    out = []
    if pkg in package_dirs:
        out.append(Path(package_dirs[pkg]).expanduser() / rest)
    for folder in (urdf_dir, *urdf_dir.parents):
        if folder.name == pkg:
            out.append(folder / rest)
        if (folder / pkg).is_dir():
            out.append(folder / pkg / rest)
    out += [urdf_dir / rest, urdf_dir / pkg / rest]
    return out


def mesh_path_candidates(
    filename: str, urdf_dir: str | Path, package_dirs: PackageDirs | None = None
) -> list[Path]:
    """Every path a URDF mesh filename may denote, most specific first.

    Args:
        filename: the ``<mesh filename>`` attribute.
        urdf_dir: folder of the URDF file.
        package_dirs: optional ``{package name: package folder}`` map.

    Returns:
        candidate paths without duplicates (they need not exist).
    """
    urdf_dir = Path(os.path.abspath(urdf_dir))
    filename = filename.strip()
    if filename.startswith("file://"):
        found = [Path(unquote(urlparse(filename).path))]
    elif filename.startswith("package://"):
        pkg, _, rest = filename[len("package://") :].partition("/")
        found = _package_candidates(pkg, rest, urdf_dir, package_dirs or {})
    else:
        path = Path(filename).expanduser()
        found = [path if path.is_absolute() else urdf_dir / path]
    unique: dict[Path, None] = {}
    for path in found:
        unique.setdefault(Path(os.path.normpath(path)), None)
    return list(unique)


def resolve_mesh_path(
    filename: str,
    urdf_dir: str | Path,
    package_dirs: PackageDirs | None = None,
    link: str | None = None,
) -> Path:
    """The existing file a URDF mesh filename denotes.

    Args:
        filename: the ``<mesh filename>`` attribute.
        urdf_dir: folder of the URDF file.
        package_dirs: optional ``{package name: package folder}`` map.
        link: the link whose geometry names the mesh, recorded in the error.

    Returns:
        the first candidate of :func:`mesh_path_candidates` that is a file.

    Raises:
        MeshNotFoundError: no candidate exists; lists the paths tried.
    """
    tried = mesh_path_candidates(filename, urdf_dir, package_dirs)
    for path in tried:
        if path.is_file():
            return path
    raise MeshNotFoundError(filename, tried, link)
