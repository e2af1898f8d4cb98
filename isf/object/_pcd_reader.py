"""Read PCL ``.pcd`` point clouds (``DATA ascii`` or ``binary``; not ``binary_compressed``).

Fields ``x y z`` are required; normals are read from ``normal_x normal_y normal_z`` or
``nx ny nz`` when present. Points PCL marks invalid (NaN coordinates) are dropped.
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import numpy as np

from ..exceptions import ObjectLoadError

__all__ = ["read_pcd"]

logger = logging.getLogger(__name__)

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


def _header_counts(header: dict[str, list[str]], key: str, path: Path,
                   default: list[str]) -> list[int]:
    """The non-negative integers of a PCD header line (``COUNT``, ``POINTS``, ...).

    Raises:
        ObjectLoadError: a value is not a non-negative integer.
    """
    words = header.get(key) or default
    try:
        values = [int(w) for w in words]
    except ValueError:
        values = [-1]
    if any(v < 0 for v in values):
        raise ObjectLoadError(f"{path}: PCD header {key} {' '.join(words)!r} must be "
                              "non-negative integers: fix the header or re-save the cloud")
    return values


def read_pcd(path: Path) -> np.ndarray:
    """Read a PCL .pcd file (DATA ascii or binary); x y z and normal_x/y/z (or nx/ny/nz).

    Args:
        path: the ``.pcd`` file.

    Returns:
        Points in file units, shape (N, 3), or points and normals, shape (N, 6), float64.

    Raises:
        ObjectLoadError: no FIELDS/DATA header, an unsupported DATA mode, a corrupt or
            truncated body, or no x y z fields.
    """
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
    counts = _header_counts(header, "COUNT", path, ["1"] * len(fields))
    if len(counts) != len(fields):
        raise ObjectLoadError(f"{path}: the PCD header has {len(fields)} FIELDS but "
                              f"{len(counts)} COUNT values: fix the header")
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if "POINTS" in header:
        (n,) = _header_counts(header, "POINTS", path, ["0"])[:1] or (0,)
    else:
        n = (_header_counts(header, "WIDTH", path, ["0"])[0]
             * _header_counts(header, "HEIGHT", path, ["1"])[0])
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
    except (ValueError, KeyError, IndexError, OverflowError) as exc:
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
    return points if normals is None else np.hstack([points, normals])
