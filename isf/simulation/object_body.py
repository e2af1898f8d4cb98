"""The object as a rigid body: convex parts for contact, mass, centre of mass and inertia.

MuJoCo collides convex geometry only (it takes the convex hull of every mesh). A mesh whose
volume fills its convex hull to within ``CONVEX_FILL`` is used as one hull; any other (also a
gripper's grooved fingertip or open pad surface, :func:`convex_parts`) is split by CoACD
(Wei et al., "Approximate Convex Decomposition for 3D Meshes with Collision-Aware Concavity
and Tree Search", SIGGRAPH 2022) into convex parts, in a child process (see
``_coacd_in_child``), and remembered per mesh for the process's life. Mass properties come from the
closed mesh with uniform density (the hull's when the mesh is not watertight), scaled to the
requested mass. Frame: the object's own (mesh) frame, metres.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from ..exceptions import InvalidInputError

__all__ = ["CONVEX_FILL", "ObjectBody", "convex_parts", "object_body"]

#: Volume / convex-hull volume above which a mesh is simulated as its hull.
CONVEX_FILL = 0.97
#: CoACD's concavity threshold (its default is 0.05) and bound on the number of parts.
COACD_THRESHOLD = 0.05
COACD_MAX_PARTS = 24

_PARTS_CACHE: dict[str, tuple[tuple[np.ndarray, np.ndarray], ...]] = {}


@dataclass(frozen=True, eq=False)
class ObjectBody:
    """A rigid object, object frame.

    Attributes:
        parts: convex parts as (vertices (V, 3) m, faces (F, 3)) pairs.
        mass: kg.
        center_of_mass: (3,), m.
        inertia: inertia tensor about the centre of mass, (3, 3), kg m^2.
    """

    parts: tuple[tuple[np.ndarray, np.ndarray], ...]
    mass: float
    center_of_mass: np.ndarray
    inertia: np.ndarray


def _convex_parts(mesh) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    key = hashlib.sha1(mesh.vertices.tobytes() + mesh.faces.tobytes()).hexdigest()
    if key in _PARTS_CACHE:
        return _PARTS_CACHE[key]
    hull = mesh.convex_hull
    if mesh.is_watertight and mesh.volume >= CONVEX_FILL * hull.volume:
        parts = ((np.asarray(hull.vertices), np.asarray(hull.faces)),)
    else:
        parts = _coacd_in_child(np.asarray(mesh.vertices, dtype=float),
                                np.asarray(mesh.faces, dtype=np.int64))
    _PARTS_CACHE[key] = parts
    return parts


def convex_parts(vertices: np.ndarray, faces: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The convex parts MuJoCo collides for a triangle mesh (vertices (V, 3) m, faces (F, 3)): its
    hull when the mesh is closed and fills ``CONVEX_FILL`` of it, else CoACD's parts (an open
    sheet, such as a curved pad's surface, becomes thin parts along it, not the slab of its
    hull). Used for the object and for every collision element of the gripper."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64),
                           process=True)
    mesh.merge_vertices()
    return _convex_parts(mesh)


_COACD_SCRIPT = """
import sys, numpy as np, coacd
coacd.set_log_level("error")
src = np.load(sys.argv[1])
pieces = coacd.run_coacd(coacd.Mesh(src["vertices"], src["faces"]), threshold=float(sys.argv[3]),
                         max_convex_hull=int(sys.argv[4]), preprocess_resolution=30,
                         resolution=1000, mcts_iterations=60, mcts_max_depth=2, mcts_nodes=10,
                         seed=0)
out = {}
for k, (v, f) in enumerate(pieces):
    out[f"v{k}"], out[f"f{k}"] = np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)
np.savez(sys.argv[2], **out)
"""


def _coacd_in_child(vertices: np.ndarray, faces: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """CoACD's convex parts, computed in a child Python process.

    CoACD's shared library, once loaded into a process that has not yet parsed a URDF with
    Pinocchio, breaks Pinocchio's URDF parser there (every later ``load_gripper`` fails): the
    library never enters isf's process.
    """
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory(prefix="isf-coacd-") as folder:
        source, target = Path(folder, "mesh.npz"), Path(folder, "parts.npz")
        np.savez(source, vertices=vertices, faces=faces)
        done = subprocess.run([sys.executable, "-c", _COACD_SCRIPT, str(source), str(target),
                               str(COACD_THRESHOLD), str(COACD_MAX_PARTS)],
                              capture_output=True, text=True, check=False)
        if done.returncode != 0 or not target.exists():
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise InvalidInputError(f"the convex decomposition (CoACD) of the object failed: {last}")
        with np.load(target) as parts:
            count = len(parts.files) // 2
            return tuple((parts[f"v{k}"], parts[f"f{k}"]) for k in range(count))


def object_body(vertices: np.ndarray, faces: np.ndarray, mass: float) -> ObjectBody:
    """The rigid body of a triangle mesh of mass ``mass`` (kg), vertices in metres."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64),
                           process=True)
    mesh.merge_vertices()
    if len(mesh.faces) < 4 or mesh.convex_hull.volume <= 0.0:
        raise InvalidInputError("the object mesh encloses no volume: it cannot be simulated")
    solid = mesh if mesh.is_watertight and mesh.volume > 0.0 else mesh.convex_hull
    scale = mass / solid.mass  # trimesh's mass at density 1
    return ObjectBody(parts=_convex_parts(mesh), mass=float(mass),
                      center_of_mass=np.asarray(solid.center_mass, dtype=float),
                      inertia=np.asarray(solid.moment_inertia, dtype=float) * scale)
