"""The grippers shipped with isf.

Layout: ``<dir>/<name>/<name>.urdf`` plus its meshes. In a wheel the repository's
top-level ``grippers/`` folder is installed as the package data folder
``isf/_bundled_grippers/``; in a source checkout (or editable install) the
``grippers/`` folder beside the ``isf`` package is used.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["bundled_gripper_dir", "bundled_grippers"]


def bundled_gripper_dir() -> Path:
    """Folder holding the bundled grippers (it may not exist in a bare checkout)."""
    package = Path(__file__).resolve().parents[1]
    data = package / "_bundled_grippers"
    return data if data.is_dir() else package.parent / "grippers"


def bundled_grippers() -> dict[str, Path]:
    """Bundled gripper names mapped to their URDF files, sorted by name."""
    root = bundled_gripper_dir()
    if not root.is_dir():
        return {}
    found = {d.name: d / f"{d.name}.urdf" for d in root.iterdir() if d.is_dir()}
    return {name: found[name] for name in sorted(found) if found[name].is_file()}
