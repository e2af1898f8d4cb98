"""The object as a rigid body: convex parts for contact, mass, centre of mass and inertia.

MuJoCo collides convex geometry only (it takes the convex hull of every mesh), so where the
collided geometry stands outside the mesh the simulated object is fatter than the real one and
a grasp whose pads touch the mesh reads as sunk into it. A closed mesh whose convex hull stands
off it by at most ``PART_TOLERANCE`` (1 mm) is used as one hull; any other (also a gripper's
grooved fingertip or open pad surface, :func:`convex_parts`) is split by CoACD (Wei et al.,
"Approximate Convex Decomposition for 3D Meshes with Collision-Aware Concavity and Tree
Search", SIGGRAPH 2022) into convex parts, in a child process (see ``_coacd_in_child``).
CoACD's concavity threshold is relative to the mesh's size (half its largest bounding-box
side), so it is set from the same tolerance (:func:`coacd_threshold`, no lower than 0.02):
the parts of a 10 cm object stand off its surface by about 1 mm, those of a 20 cm one by up
to about 2 mm, not the 5 mm of CoACD's default. Parts are kept
per mesh for the process's life and on disk under ``<cache>/convex-parts/``
(:func:`isf.assets.cache_dir`), so a mesh is decomposed once per machine. Mass properties come
from the closed mesh with uniform density (the hull's when the mesh is not watertight), scaled
to the requested mass. Frame: the object's own (mesh) frame, metres.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass

import numpy as np

from ..exceptions import InvalidInputError

__all__ = ["PART_TOLERANCE", "ObjectBody", "coacd_threshold", "convex_parts", "distances_to_mesh",
           "hull_standoff", "object_body"]

#: The default distance, m, by which the convex parts may stand off the mesh: a closed mesh
#: whose hull stands off it by no more is its hull; CoACD's concavity threshold is this over
#: half the mesh's largest bounding-box side, within ``COACD_THRESHOLD_RANGE``.
PART_TOLERANCE = 0.001
#: Spacing (m) of the points on the hull whose distance from the mesh is its standoff.
HULL_SAMPLE_SPACING = 0.001
#: The thresholds used, at most CoACD's default (0.05). Below 0.02 its time grows steeply on
#: scanned objects (minutes for a 21 cm box), so an object larger than 2 * tolerance / 0.02
#: (10 cm at 1 mm) is decomposed at 0.02: its parts may stand off it by up to about
#: 0.01 times its largest side (docs/validate.md measures it).
COACD_THRESHOLD_RANGE = (0.02, 0.05)
#: Version of the decomposition's settings, part of the disk cache's key.
_PARTS_FORMAT = "isf-convex-parts/2"

_PARTS_CACHE: dict[str, tuple[tuple[np.ndarray, np.ndarray], ...]] = {}
log = logging.getLogger(__name__)


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


def coacd_threshold(vertices: np.ndarray, tolerance: float = PART_TOLERANCE) -> float:
    """CoACD's concavity threshold for a mesh with vertices (V, 3), m: ``tolerance`` (m) over
    half the largest side of its bounding box, clipped to ``COACD_THRESHOLD_RANGE``."""
    half_side = 0.5 * float(np.ptp(np.asarray(vertices, dtype=float), axis=0).max())
    low, high = COACD_THRESHOLD_RANGE
    return float(np.clip(tolerance / max(half_side, 1e-9), low, high))


def distances_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Exact distance (m) of each point (P, 3) from a triangle mesh (vertices (V, 3) m, faces
    (F, 3)), by coal (``isf.collision.checker.mesh_distances``), (P,)."""
    from ..collision.checker import mesh_bvh, mesh_distances

    return mesh_distances(mesh_bvh(vertices, faces), points)


def hull_standoff(mesh, hull) -> float:
    """How far (m) the convex hull of a closed ``trimesh.Trimesh`` stands off it: the largest
    distance from the mesh (:func:`distances_to_mesh`) of points spread over the hull's faces,
    every ``HULL_SAMPLE_SPACING`` on average (at least 2000, at most 20000; fixed seed), and of
    its face centres."""
    import trimesh

    count = int(np.clip(hull.area / HULL_SAMPLE_SPACING ** 2, 2000, 20000))
    points = np.concatenate([trimesh.sample.sample_surface(hull, count, seed=0)[0],
                             np.asarray(hull.triangles_center)])
    return float(distances_to_mesh(points, mesh.vertices, mesh.faces).max())


def _convex_parts(mesh, tolerance: float) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    vertices = np.ascontiguousarray(mesh.vertices, dtype=float)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    threshold = coacd_threshold(vertices, tolerance)
    key = hashlib.sha1(f"{_PARTS_FORMAT} {tolerance!r} {threshold!r}".encode()
                       + vertices.tobytes() + faces.tobytes()).hexdigest()
    if key in _PARTS_CACHE:
        return _PARTS_CACHE[key]
    # stored parts exist only for a mesh whose hull was refused: looking them up first spares
    # a later process the hull test's thousands of exact distances
    parts = _stored_parts(key)
    if parts is None:
        hull = mesh.convex_hull
        if mesh.is_watertight and hull_standoff(mesh, hull) <= tolerance:
            parts = ((np.asarray(hull.vertices), np.asarray(hull.faces)),)
        else:
            log.info("making the convex parts of a %d-face mesh (CoACD, threshold %.3f): "
                     "tens of seconds for a scanned object, once: they are kept in %s",
                     len(faces), threshold, _parts_file(key).parent)
            parts = _coacd_in_child(vertices, faces, threshold, closed=mesh.is_watertight)
            _store_parts(key, parts)
    _PARTS_CACHE[key] = parts
    return parts


def _parts_file(key: str):
    from ..assets import cache_dir

    return cache_dir() / "convex-parts" / f"{key}.npz"


def _stored_parts(key: str) -> tuple[tuple[np.ndarray, np.ndarray], ...] | None:
    """The parts stored on disk under ``key``, or None (none stored, or a file that does not
    read: it is decomposed again and rewritten)."""
    try:
        return _read_parts(_parts_file(key)) or None
    except (OSError, ValueError, KeyError):
        return None


def _read_parts(path) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The parts of a file as CoACD's child process and :func:`_store_parts` write them:
    arrays ``v0, f0, v1, f1, ...``."""
    with np.load(path, allow_pickle=False) as stored:
        return tuple((stored[f"v{k}"], stored[f"f{k}"]) for k in range(len(stored.files) // 2))


def _store_parts(key: str, parts: tuple[tuple[np.ndarray, np.ndarray], ...]) -> None:
    """Write the parts for later processes (:func:`isf.output_files.write_atomically`: a reader
    never sees half a file); a cache that cannot be written is skipped."""
    import io

    from ..exceptions import OutputFileError
    from ..output_files import write_atomically

    path = _parts_file(key)
    data = io.BytesIO()
    np.savez(data, **{f"{name}{k}": array for k, (v, f) in enumerate(parts)
                      for name, array in (("v", v), ("f", f))})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(path, data.getvalue(), "convex parts cache file")
    except (OSError, OutputFileError):
        return


def convex_parts(vertices: np.ndarray, faces: np.ndarray, tolerance: float = PART_TOLERANCE
                 ) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The convex parts MuJoCo collides for a triangle mesh (vertices (V, 3) m, faces (F, 3)): its
    hull when the mesh is closed and the hull stands off it by at most ``tolerance`` (m,
    :func:`hull_standoff`), else CoACD's parts (an open sheet, such as a curved pad's surface,
    becomes thin parts along it, not the slab of its hull), standing off the mesh by about
    ``tolerance`` (:func:`coacd_threshold`). Used for the object and for every collision
    element of the gripper."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64),
                           process=True)
    mesh.merge_vertices()
    return _convex_parts(mesh, tolerance)


_COACD_SCRIPT = """
import sys, numpy as np, coacd
coacd.set_log_level("error")
src = np.load(sys.argv[1])
pieces = coacd.run_coacd(coacd.Mesh(src["vertices"], src["faces"]), threshold=float(sys.argv[3]),
                         max_convex_hull=-1, merge=False, preprocess_mode=sys.argv[4],
                         preprocess_resolution=30,
                         resolution=1000, mcts_iterations=60, mcts_max_depth=2, mcts_nodes=10,
                         seed=0)
out = {}
for k, (v, f) in enumerate(pieces):
    out[f"v{k}"], out[f"f{k}"] = np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)
np.savez(sys.argv[2], **out)
"""


def _coacd_in_child(vertices: np.ndarray, faces: np.ndarray, threshold: float,
                    closed: bool) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """CoACD's convex parts at concavity ``threshold``, computed in a child Python process.

    Parts are not merged afterwards: CoACD's merging pass, quadratic in the number of parts,
    only lowers their count, at about twice the time on scanned objects. A ``closed`` mesh is
    decomposed as it is: CoACD's manifold preprocessing remeshes on a voxel grid (30 cells
    along the largest side), which would blur the mesh by more than the tolerance; an open
    surface (a pad) needs it to become a solid.

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
                               repr(threshold), "off" if closed else "auto"],
                              capture_output=True, text=True, check=False)
        if done.returncode != 0 or not target.exists():
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise InvalidInputError(f"the convex decomposition (CoACD) of the object failed: {last}")
        return _read_parts(target)


def object_body(vertices: np.ndarray, faces: np.ndarray, mass: float,
                tolerance: float = PART_TOLERANCE) -> ObjectBody:
    """The rigid body of a triangle mesh of mass ``mass`` (kg), vertices in metres, collided as
    convex parts within ``tolerance`` (m) of the mesh
    (:func:`isf.simulation.object_body.convex_parts`)."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64),
                           process=True)
    mesh.merge_vertices()
    if len(mesh.faces) < 4 or mesh.convex_hull.volume <= 0.0:
        raise InvalidInputError("the object mesh encloses no volume: it cannot be simulated")
    solid = mesh if mesh.is_watertight and mesh.volume > 0.0 else mesh.convex_hull
    scale = mass / solid.mass  # trimesh's mass at density 1
    return ObjectBody(parts=_convex_parts(mesh, tolerance), mass=float(mass),
                      center_of_mass=np.asarray(solid.center_mass, dtype=float),
                      inertia=np.asarray(solid.moment_inertia, dtype=float) * scale)
