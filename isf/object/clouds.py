"""Raw point clouds: read a file or array as it is, thin it by voxels, estimate normals.

:func:`isf.load_object` reads clouds too, but samples and orients them as a whole object;
scenes (:mod:`isf.scene`) need the raw points, to place them in a camera's frame first, and
orient their normals towards the camera that saw each point.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import ObjectLoadError
from ._normals import estimate_normals, voxel_downsample
from ._readers import read_source

__all__ = ["estimate_normals", "read_cloud", "voxel_downsample"]


def read_cloud(source) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The points of a point-cloud file (PLY without faces, PCD, XYZ/TXT, NPY) or array.

    Args:
        source: a file path, or an array (N, 3) (points) or (N, 6) (points and normals).

    Returns:
        (points (N, 3), normals (N, 3) as given or None, the source's name), file units.

    Raises:
        ObjectLoadError: the source cannot be read, or holds a mesh rather than a cloud.
    """
    raw, name = read_source(source)
    if raw.points is None:
        raise ObjectLoadError(f"{name} is a mesh, not a point cloud: a scene is what a camera "
                              "saw; load a mesh with isf.load_object")
    normals = None if raw.normals is None else np.asarray(raw.normals, dtype=np.float64)
    return np.asarray(raw.points, dtype=np.float64), normals, name
