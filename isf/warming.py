"""isf's compiled kernels, and compiling them before anything is timed.

The inner loops of isf are numba kernels: the moment sums and steps of IPFO
(:mod:`isf.fitting.moment_kernels`), the nearest-point search (:mod:`isf.search.nearest`), the
correspondence filters (:mod:`isf.fitting.correspondence`), the finger step's active set
(:mod:`isf.fitting._box_qp`), the kinematics (:mod:`isf.gripper.chain`), the repair's rows
(:mod:`isf.repair.rows`) and the collision checks (``isf.collision.kernel``). numba compiles
a kernel at its first call and caches the machine code on disk (in the package's
``__pycache__`` folders, or in numba's user cache when those are read-only;
``NUMBA_CACHE_DIR`` moves it; :mod:`isf.compiled.cache` drops cached kernels whose sources
changed, or the sources of the modules they use). So the first run after installing or
upgrading isf compiles them (about a minute on a 2-core machine, compiling the engine's and
the checks' kernels in two processes), and later runs load them in about a second.

:func:`warm_up` compiles (or loads) every kernel on tiny inputs of the types the engine
passes, so that the cost lands where the caller wants it: ``isf plan`` calls it before
planning (and says so when it takes a while), the benchmark scripts before timing.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pinocchio as pin
import trimesh

from .collision.checker import CollisionChecker
from .collision.convex_elements import ConvexElements
from .collision.kernel import check_elements
from .collision.voxels import SurfaceVoxels
from .fitting.correspondence import match
from .fitting.fit import fit_many
from .gripper.model import ContactSurface, Gripper, LinkGeometry
from .object.surface import ObjectSurface
from .repair.clearance import ClearanceRepair
from .repair.rows import deepest_rows, undecided
from .search.nearest import NearestPoints
from .search.point_grid import PointGrid

__all__ = ["warm_up"]


def _tiny_gripper() -> Gripper:
    """One revolute joint (about x) carrying a 14 x 14 mm pad 5 cm along x, facing -z (64
    points, 8 of them on the coarsest pyramid level: enough pairs to fit)."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "joint")
    model.lowerPositionLimit[:], model.upperPositionLimit[:] = -1.0, 1.0
    model.addFrame(pin.Frame("link", joint, pin.SE3.Identity(), pin.FrameType.BODY))
    grid = np.stack(np.meshgrid(*[np.linspace(-0.007, 0.007, 8)] * 2), axis=-1).reshape(-1, 2)
    pad = ContactSurface("pad", "link", np.c_[grid + [0.05, 0.0], np.zeros(64)],
                         np.tile([0.0, 0.0, -1.0], (64, 1)), 2e-4)
    return Gripper("warm-up", model, (pad,), np.zeros(1))


def _check_collisions() -> None:
    """Collision checks of a convex block (the pad's) and a non-convex ring above it against a
    closed mesh, apart and pressed in, and the repair of the pressed-in state."""
    tiny = _tiny_gripper()
    block = trimesh.creation.box(extents=(0.02, 0.02, 0.01))
    block.apply_translation((0.05, 0.0, 0.005))  # the pad lies on its lower face
    ring = trimesh.creation.torus(0.006, 0.002, major_sections=12, minor_sections=6)
    ring.apply_translation((0.05, 0.0, 0.02))
    gripper = Gripper("warm-up", tiny.model, tiny.surfaces, tiny.q_initial, geometries=(
        LinkGeometry("link", "block", block.vertices, block.faces),
        LinkGeometry("link", "ring", ring.vertices, ring.faces)))
    cube = trimesh.creation.box(extents=(0.04, 0.04, 0.03))
    cube.apply_translation((0.05, 0.0, -0.016))
    points, faces = trimesh.sample.sample_surface(cube, 2000, seed=0)
    obj = ObjectSurface(points, cube.face_normals[faces], spacing=0.001, mesh_vertices=cube.vertices,
                        mesh_faces=cube.faces)
    checker = CollisionChecker(gripper, obj)
    for depth in (0.0, 0.004, 0.02):  # apart (clearance measured), block in, ring in
        T = np.eye(4)
        T[2, 3] = -depth
        checker.check(T, np.zeros(1))
    ClearanceRepair(gripper, obj).repair(T, np.zeros(1))  # the repair's clearance rows


def warm_up() -> float:
    """Compile, or load from the cache, every compiled kernel of isf; returns the seconds taken.

    It fits a one-joint gripper onto a small plane (the engine's own calls, so its own
    argument types), once more with IPFO pausing for Python (as it does for OSQP finger steps
    and for joints without compiled kinematics), asks for nearest points as the repair does,
    runs the repair's convex-element test and row selection, the voxel
    tests, collision checks of a convex and a non-convex element against a mesh, apart and
    pressed in, and the repair of the pressed-in state. When the kernels of the checks and the
    repair are not compiled yet and the machine has a second core, a second process compiles
    them (into the same cache) while this one compiles the engine's.
    """
    start = time.perf_counter()
    helper = None
    if (os.cpu_count() or 1) > 1 and not _cached(check_elements):
        helper = subprocess.Popen([sys.executable, "-c", "from isf.warming import _warm_checks; _warm_checks()"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _warm_engine()
    if helper is not None:
        helper.wait()  # its kernels load from the cache below (or compile here, had it failed)
    _warm_checks()
    return time.perf_counter() - start


def _cached(kernel) -> bool:
    """Whether numba's disk cache holds compiled code of ``kernel`` for this source (False when
    that cannot be told)."""
    try:
        return bool(kernel._cache._cache_file._load_index())
    except Exception:  # numba internals moved: assume cached, so nothing runs twice
        return True


def _warm_engine() -> None:
    """The kernels of the ISF engine, with the engine's calls."""
    grid = np.stack(np.meshgrid(*[np.linspace(-0.02, 0.02, 41)] * 2), axis=-1).reshape(-1, 2)
    plane = ObjectSurface(np.c_[grid + [0.05, 0.0], np.zeros(len(grid))],
                          np.tile([0.0, 0.0, 1.0], (len(grid), 1)), spacing=0.001)
    T = np.eye(4)
    T[2, 3] = 0.001  # the pad 1 mm above the plane
    fit_many(_tiny_gripper(), plane, T[None])
    paused = _tiny_gripper()
    paused._chain = None  # as for joints without compiled kinematics: IPFO pauses for Pinocchio
    fit_many(paused, plane, T[None], np.array([[0.1]]))  # a tilted pad: the joint turns
    plane.nearest(plane.points[:2])  # as the collision repair asks
    match(plane, plane.points[:8] + [0.0, 0.0, 0.001], outlier_factor=3.0, outlier_floor=0.005,
          reject_duplicates=True)


def _warm_checks() -> None:
    """The kernels of the collision checks and the repair."""
    points = np.random.default_rng(0).uniform(-0.01, 0.01, (50, 3))
    search = NearestPoints(points, graph=True)  # the graph's neighbour lists, sorted
    search.query_k(points[:2], 6)
    search.query_within(points[:2], 0.01)  # a bounded search
    box = trimesh.creation.box(extents=(0.01, 0.01, 0.01))
    ConvexElements([(box.vertices, box.faces)], np.zeros(1), np.zeros(1)).rows(
        np.eye(4), np.eye(3)[None], np.zeros((1, 3)), PointGrid(points, 0.004), 0.003, 12)
    one, element = np.zeros(1), np.zeros(1, dtype=np.int64)  # the repair's row selection
    deepest_rows(one, element, 1, 0.008, 12)
    undecided(one, element, one, element, 1, 0.008, 12, 1e-12)
    voxels = SurfaceVoxels(box.vertices, box.faces)  # the collision checks' voxels
    voxels.clear(box.vertices, box.vertices), voxels.distance_below(box.vertices)
    _check_collisions()
