"""isf's compiled kernels, and compiling them before anything is timed.

The inner loops of isf are numba kernels: the moment sums and steps of IPFO
(:mod:`isf.fitting.moment_kernels`), the nearest-point search (:mod:`isf.search.nearest`), the
correspondence filters (:mod:`isf.fitting.correspondence`), the finger step's active set
(:mod:`isf.fitting._box_qp`), the kinematics (:mod:`isf.gripper.chain`), the repair's rows
(:mod:`isf.repair.rows`) and the collision checks (``isf.collision.kernel``). numba compiles
a kernel at its first call and caches the machine code on disk (in the package's
``__pycache__`` folders, or in numba's user cache when those are read-only;
``NUMBA_CACHE_DIR`` moves it; :mod:`isf.compiled.cache` drops cached kernels whose sources
changed, or the sources of the modules they use, and those it cannot load). So the first
run after installing or upgrading isf compiles them (the engine's kernels and, side by side on
a machine with two cores, the checks' and the repair's: docs/benchmarks.md, "First run"), and
later runs load them in about a second.

:func:`warm_up` compiles (or loads) every kernel on tiny inputs of the types the engine
passes, so that the cost lands where the caller wants it: ``isf plan`` calls it before
planning (and says so when it takes a while), the benchmark scripts before timing.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio as pin
import trimesh
from numba.core import event
from numba.core.dispatcher import Dispatcher

from .collision.checker import CollisionChecker
from .collision.convex_elements import ConvexElements
from .collision.voxels import SurfaceVoxels
from .compiled.cache import cache_folder
from .compiled.healing import logger
from .compiled.lock import compile_lock
from .compiled.workers import compiled_name, start_worker
from .config import FitConfig
from .fitting.correspondence import match
from .fitting.engine import score_fit
from .fitting.fit import fit_many
from .fitting.reclosing import reclose_joints
from .gripper.model import ContactSurface, Gripper, LinkGeometry
from .object.surface import ObjectSurface
from .repair.clearance import ClearanceRepair
from .repair.rows import deepest_rows, undecided
from .result import FitStatus
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


def warm_up(progress: Callable[[int, int], None] | None = None) -> float:
    """Compile, or load from the cache, every compiled kernel of isf; returns the seconds taken.

    It fits a one-joint gripper onto a small plane (the engine's own calls, so its own
    argument types), once more with IPFO pausing for Python (as it does for OSQP finger steps
    and for joints without compiled kinematics), asks for nearest points as the repair does,
    runs the repair's convex-element test and row selection, the voxel
    tests, collision checks of a convex and a non-convex element against a mesh, apart and
    pressed in, and the repair of the pressed-in state.

    When kernels must be compiled: one process at a time compiles into a cache
    (``isf.compiled.lock.compile_lock``; another waits, then loads); on a machine with a
    second core a worker process (``isf.compiled.workers``, ended if this one dies)
    compiles the checks' and the repair's kernels while this one compiles the engine's; and
    ``progress(done, total)`` is called with ``done`` 0 and then as each kernel is
    compiled, ``total`` being the number of kernels not found in the cache (never called
    when all load from it).
    """
    start = time.perf_counter()
    folder = cache_folder(Path(__file__).parent / "__init__.py")
    with compile_lock(folder, waiting=lambda: logger.info(
            "waiting for another process compiling isf's kernels into %s", folder)):
        pending = {compiled_name(kernel) for kernel in _kernels() if not _cached(kernel)}
        if pending:
            _compile(pending, progress)
        for part in _PARTS:
            part()  # loads what the workers compiled (or compiles what one failed to)
    return time.perf_counter() - start


_NOT_WARMED = frozenset({
    # called only from Python by the moment form's reference paths (isf.fitting._moments,
    # isf.fitting._palm_step), never by a fit or a plan
    "isf.fitting.moment_kernels.palm_motions", "isf.fitting.moment_kernels.palm_systems",
})
"""The kernels of the loaded modules that :func:`warm_up` leaves to their first call."""


def _kernels() -> list:
    """The numba dispatchers of isf's loaded modules that :func:`warm_up` compiles: those that
    compile on their own (not those numba inlines into their callers), but for
    :data:`_NOT_WARMED`, each once."""
    found = {}
    for name, module in list(sys.modules.items()):
        if name == "isf" or name.startswith("isf."):
            for value in list(vars(module).values()):
                if (isinstance(value, Dispatcher) and value.targetoptions.get("inline") != "always"
                        and compiled_name(value) not in _NOT_WARMED):
                    found[id(value)] = value
    return list(found.values())


def _cached(kernel) -> bool:
    """Whether numba's disk cache holds compiled code of ``kernel`` for this source (True when
    that cannot be told: the count of kernels to compile then leaves it out)."""
    try:
        return bool(kernel._cache._cache_file._load_index())
    except Exception:  # numba internals moved, or an unreadable index (healed when loaded)
        return True


class _Count:
    """The kernels compiled so far, by name, from this process and its workers."""

    def __init__(self, pending: set[str], progress: Callable[[int, int], None] | None):
        self.pending, self.progress = pending, progress
        self.done: set[str] = set()
        self.lock = threading.Lock()
        if progress is not None:
            progress(0, len(pending))

    def add(self, name: str) -> None:
        with self.lock:
            if name not in self.pending or name in self.done:
                return
            self.done.add(name)
            if self.progress is not None:
                self.progress(len(self.done), len(self.pending))

    def read(self, stream) -> None:
        for line in stream:  # until the worker ends
            self.add(line.strip())


def _compile(pending: set[str], progress: Callable[[int, int], None] | None) -> None:
    """Compile the kernels of every part of the warm-up: the first here, the others in worker
    processes while cores allow, counting ``pending`` down through ``progress``."""
    count = _Count(pending, progress)

    class Listener(event.Listener):
        def on_start(self, event_):
            pass

        def on_end(self, event_):
            count.add(compiled_name(event_.data["dispatcher"]))

    workers = [start_worker(f"{__name__}:{part.__name__}")
               for part in _PARTS[1:(os.cpu_count() or 1)]]
    readers = [threading.Thread(target=count.read, args=(worker.stdout,), daemon=True)
               for worker in workers]
    for reader in readers:
        reader.start()
    listener = Listener()
    event.register("numba:compile", listener)
    try:
        for part in _PARTS[:len(_PARTS) - len(workers)]:
            part()
        for worker, reader in zip(workers, readers):
            worker.wait()
            reader.join()
    finally:
        event.unregister("numba:compile", listener)
        for worker in workers:  # a worker still running here (an exception above) ends now
            worker.stdin.close()
            worker.wait()


def _warm_engine() -> None:
    """The kernels of the ISF engine, with the engine's calls: first the compiled kinematics
    (which the checks' part then loads from the cache), then the fits."""
    _tiny_gripper().link_kinematics_many(np.zeros((1, 1)))
    plane, T = _plane(), _pad_pose()
    fit_many(_tiny_gripper(), plane, T[None])
    paused = _tiny_gripper()
    paused._chain = None  # as for joints without compiled kinematics: IPFO pauses for Pinocchio
    fit_many(paused, plane, T[None], np.array([[0.1]]))  # a tilted pad: the joint turns


def _pad_pose() -> np.ndarray:
    """The tiny gripper's pose (4, 4) that puts its pad 1 mm above :func:`_plane`."""
    T = np.eye(4)
    T[2, 3] = 0.001
    return T


def _plane() -> ObjectSurface:
    """A 4 x 4 cm plane of 1681 points at z = 0, normals +z, under the tiny gripper's pad."""
    grid = np.stack(np.meshgrid(*[np.linspace(-0.02, 0.02, 41)] * 2), axis=-1).reshape(-1, 2)
    return ObjectSurface(np.c_[grid + [0.05, 0.0], np.zeros(len(grid))],
                         np.tile([0.0, 0.0, 1.0], (len(grid), 1)), spacing=0.001)


def _warm_checks() -> None:
    """The kernels of the collision checks and the repair, and the engine's kernels that only
    finished fits, the repair and the centring call (a fit's score, nearest points, the
    correspondence filter, the finger step's bounded solve). Those that need no k-d tree and no
    kinematics come first: the engine's part compiles both at once, and they are then in the
    cache when this part needs them."""
    points = np.random.default_rng(0).uniform(-0.01, 0.01, (50, 3))
    box = trimesh.creation.box(extents=(0.01, 0.01, 0.01))
    ConvexElements([(box.vertices, box.faces)], np.zeros(1), np.zeros(1)).rows(
        np.eye(4), np.eye(3)[None], np.zeros((1, 3)), PointGrid(points, 0.004), 0.003, 12)
    one, element = np.zeros(1), np.zeros(1, dtype=np.int64)  # the repair's row selection
    deepest_rows(one, element, 1, 0.008, 12)
    undecided(one, element, one, element, 1, 0.008, 12, 1e-12)
    voxels = SurfaceVoxels(box.vertices, box.faces)  # the collision checks' voxels
    voxels.clear(box.vertices, box.vertices), voxels.distance_below(box.vertices)
    search = NearestPoints(points, graph=True)  # the graph's neighbour lists, sorted
    search.query_k(points[:2], 6)
    search.query_within(points[:2], 0.01)  # a bounded search
    plane, T = _plane(), _pad_pose()
    score_fit(_tiny_gripper(), plane, T, np.zeros(1), FitConfig(), FitStatus.CONVERGED, (), 0.0)
    reclose_joints(_tiny_gripper(), plane, T, np.zeros(1))  # the finger step's solve, from Python
    plane.nearest(plane.points[:2])  # as the collision repair asks
    match(plane, plane.points[:8] + [0.0, 0.0, 0.001], outlier_factor=3.0, outlier_floor=0.005,
          reject_duplicates=True)
    _check_collisions()


_PARTS = (_warm_engine, _warm_checks)
"""The warm-up's parts: with a worker per extra core, the first runs in this process and the
last ones in the workers. Where two parts use a kernel, one compiles it before the other needs
it, which then loads it from the cache: no kernel is compiled twice but the array copy
(:func:`isf.compiled.arrays.copy_into`), a few tenths of a second, which each part needs from
its first kernels on."""
