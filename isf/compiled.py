"""isf's compiled kernels, and compiling them before anything is timed.

The inner loops of isf are numba kernels: the moment sums and steps of IPFO
(:mod:`isf.moment_kernels`), the nearest-point search (:mod:`isf.nearest`), the
correspondence filters (:mod:`isf.correspondence`), the finger step's active set
(:mod:`isf.box_qp`), the kinematics (:mod:`isf.chain`) and the repair's QP
(:mod:`isf.dense_qp`). numba compiles a kernel at its first call and caches the
machine code on disk (in the package's ``__pycache__`` folders, or in numba's user cache
when those are read-only; ``NUMBA_CACHE_DIR`` moves it). So the first run after
installing or upgrading isf compiles them, about half a minute on a 2-core machine, and
later runs load them in under a second.

:func:`warm_up` compiles (or loads) every kernel on tiny inputs of the types the engine
passes, so that the cost lands where the caller wants it: ``isf plan`` calls it before
planning (and says so when it takes a while), the benchmark scripts before timing.
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin

from .box_qp import solve_box_qps
from .chain import KinematicChain
from .correspondence import match_many
from .dense_qp import solve_dense_qp
from .gripper import LinkKinematics
from .moment_kernels import palm_motions, points_in_object
from .moments import PairMoments
from .object_surface import ObjectSurface
from .segments import Segments

__all__ = ["warm_up"]


def _one_joint_model() -> tuple[pin.Model, int]:
    """A model with one revolute joint and a frame on its link."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "joint")
    frame = model.addFrame(pin.Frame("link", joint, pin.SE3.Identity(), pin.FrameType.BODY))
    return model, frame


def warm_up() -> float:
    """Compile, or load from the cache, every compiled kernel of isf; returns the seconds taken."""
    start = time.perf_counter()
    one = np.zeros(1, dtype=np.int64)
    point, normal = np.array([[0.0, 0.0, 0.01]]), np.array([[0.0, 0.0, 1.0]])
    model, frame = _one_joint_model()
    chain = KinematicChain.from_model(model)
    R, p, Jv, Jw = chain.frame_kinematics(np.zeros((1, 1)), np.array([frame]))
    links = LinkKinematics(R, p, Jv, Jw)
    T = np.eye(4)[None]
    moments = PairMoments(one, one, point, normal, point, normal, 1, 1)
    moments.errors(T, links, 0.01)
    moments.palm_update(T, links, 0.01, 0.1)
    moments.palm_system(T, links, 0.01)
    moments.finger_system(T, links, 0.01)
    palm_motions(np.eye(6)[None], np.zeros((1, 6)), np.zeros((1, 3)), 0.1)
    points_in_object(T, R, p, one, one, point, normal)
    surface = ObjectSurface(point, -normal, spacing=0.001)
    surface.nearest(point, np.zeros(1, dtype=np.int64))
    match_many(surface, point, Segments.single(1), outlier_factor=3.0, outlier_floor=0.001,
               reject_duplicates=True, normals=normal, max_normal_angle=1.0)
    solve_box_qps(np.eye(2)[None], np.ones((1, 2)), -np.ones((1, 2)), np.ones((1, 2)))
    solve_dense_qp(np.eye(2), np.ones(2), np.ones((1, 2)), np.zeros(1), np.ones(1))
    return time.perf_counter() - start
