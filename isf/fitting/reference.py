"""Plain-Python reference of ISF (paper Algorithms 1 and 2): the test oracle of the compiled engine.

:func:`ipfo` is Algorithm 1 (iterative palm-finger optimisation for fixed correspondences) and
:func:`fit` is Algorithm 2 (the pyramid of correspondence searches and IPFO runs with the
displacement-ratio stop rule), written as the paper's loops in numpy and scipy (kinematics from
Pinocchio), one fit at a time, without numba. They follow :class:`isf.FitConfig` exactly as the
compiled engine does (:class:`isf.fitting.engine.LockstepFitter`, behind :func:`isf.fit` and
:func:`isf.fit_many`), so both follow the same trajectory up to round-off;
``tests/test_reference.py`` compares whole fits.
Algorithm 3 is :func:`isf.planning.planner.plan`.

:class:`PairBatch` evaluates the matched pairs of many fits pair by pair, in numpy.
"""

from __future__ import annotations

import itertools
import time
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from scipy.spatial import cKDTree

from ..config import FitConfig
from ..gripper.model import Gripper, LinkKinematics
from ..object.surface import ObjectSurface
from ..result import FitResult, FitStatus, History, IterationRecord
from ..se3 import cross
from .segments import Segments

__all__ = ["IPFOOutcome", "Pairs", "PairBatch", "box_qp", "correspondences", "finger_step", "fit",
           "ipfo", "palm_step", "palm_system"]

STILL = 1e-12
"""A level's displacement ``e_s`` (m) at or below which the gripper counts as still (eta = 1)."""

PALM_RIDGE = 1e-12
"""Ridge of the palm step's normal equations, relative to their trace (as the engine's)."""

FINGER_RIDGE = 1e-14
"""Ridge of the finger step's normal equations, relative to their trace (as the engine's)."""


class Pairs(NamedTuple):
    """The matched pairs of one fit (paper IV-B: nearest neighbours, outliers and duplicates
    removed).

    Attributes:
        rows: indices of the matched contact points into the gripper's points, (K,).
        targets: indices of their nearest object points into ``ObjectSurface.points``, (K,).
        distances: Euclidean distance of every queried contact point to its nearest object point,
            (M,) for the M points queried, metres.
    """

    rows: np.ndarray
    targets: np.ndarray
    distances: np.ndarray


class IPFOOutcome(NamedTuple):
    """What :func:`ipfo` returns for one fit.

    Attributes:
        T_object_gripper: palm pose, (4, 4).
        q: joints, (n_joints,).
        links: contact-link kinematics at ``q`` (arrays (L, ...)).
        error: E at the result, m^2 (eq. 9a).
        errors: E after each kept alternation (the paper's Fig. 5b), m^2.
    """

    T_object_gripper: np.ndarray
    q: np.ndarray
    links: LinkKinematics
    error: float
    errors: tuple[float, ...]


def fit(gripper: Gripper, obj: ObjectSurface, T_object_gripper: np.ndarray,
        q: np.ndarray | None = None, config: FitConfig | None = None) -> FitResult:
    """Iterative surface fitting (Algorithm 2) of one gripper state, pair by pair in numpy.

    The reference of the compiled engine (:func:`isf.fit`, :func:`isf.fit_many`,
    :class:`isf.fitting.engine.LockstepFitter`), which follows the same steps for many fits at
    once; IPFO is :func:`ipfo` (Algorithm 1); the planner's loop is
    :func:`isf.planning.planner.plan` (Algorithm 3).

    Args:
        gripper: the gripper.
        obj: the object surface.
        T_object_gripper: initial palm pose ``R_c, t_c``, (4, 4), metres.
        q: initial joints ``d_0``, (n_joints,); default ``gripper.q_initial``.
        config: parameters (``L = levels``, ``I0 = max_iterations``, ``eps0 = tolerance``, ...);
            default the paper's.

    Returns:
        the :class:`FitResult` (its ``time`` is this function's wall time).
    """
    started = time.perf_counter()
    config = FitConfig() if config is None else config
    T = np.array(T_object_gripper, dtype=float)
    q = gripper.clip(gripper.q_initial if q is None else q)
    links = _kinematics(gripper, q)  # Line 2: dF = T(dF; R_c, t_c, d_0)
    search = cKDTree(obj.points)
    records: list[IterationRecord] = []
    status = FitStatus.MAX_ITERATIONS
    for level in range(config.levels - 1, -1, -1):  # Line 3: l = L-1, ..., 0
        rows = np.flatnonzero(gripper.level_mask(level))  # Line 4: S^f = downsample(dF, 2^l)
        max_iterations = max(1, config.max_iterations // 2**level)  # I_l = I0 / 2^l
        eps = 2.0**level * config.tolerance  # eps_l = 2^l eps0
        start = _place(gripper, T, links, rows)[0]  # Line 5: S^f_0 = S^f, e_s = inf, eta = 0
        e_s, eta, it = np.inf, 0.0, 0
        while True:  # Line 6, tested at the end: stop when eta is in 1 +- eps_l or it = I_l
            e_sp = e_s  # Line 7
            points, normals = _place(gripper, T, links, rows)
            pairs = correspondences(gripper, obj, search, rows, points, normals, config)  # 8-9
            if len(pairs.rows) < config.min_pairs:
                return _result(gripper, obj, search, config, T, q, FitStatus.LOST_CONTACT, records,
                               started)
            matched = PairBatch(gripper, Segments.single(len(pairs.rows)), pairs.rows,
                                obj.points[pairs.targets], obj.normals[pairs.targets])
            if not records:  # iteration 0: the start pose and the pairs matched there
                records.append(_record(matched, T, q, links, level, 0,
                                       _error(matched, T, links, config.normal_weight),
                                       np.nan, ()))
            T, q, links, error, errors = ipfo(matched, T, q, links, config)  # Line 10
            moved = _place(gripper, T, links, rows)[0]  # Lines 11-13: S^f, dF and d_0 follow
            it += 1
            e_s = np.linalg.norm(moved - start)  # Line 14: e_s = ||S^f - S^f_0||
            eta = 1.0 if e_s <= STILL else e_s / e_sp  # eta = e_s / e_s,p
            records.append(_record(matched, T, q, links, level, it, error, eta, errors))
            converged = 1.0 - eps <= eta <= 1.0 + eps
            if converged or it >= max_iterations:
                break
        status = FitStatus.CONVERGED if converged else FitStatus.MAX_ITERATIONS
    return _result(gripper, obj, search, config, T, q, status, records, started)  # Line 17


def _record(pairs: PairBatch, T: np.ndarray, q: np.ndarray, links: LinkKinematics, level: int,
            iteration: int, error: float, eta: float, errors: tuple[float, ...]) -> IterationRecord:
    """The :class:`IterationRecord` of the state ``T``, ``q`` (``links``) with ``pairs``."""
    distance = np.abs(pairs.residuals(T[None], *_evaluate(pairs, links)[:2])[0])
    return IterationRecord(level=level, iteration=iteration,
                           mean_distance=distance.sum() / len(distance), error=error,
                           n_pairs=len(distance), q=q, T_object_gripper=T,
                           displacement_ratio=eta, ipfo_errors=errors)


def ipfo(pairs: PairBatch, T: np.ndarray, q: np.ndarray, links: LinkKinematics,
         config: FitConfig) -> IPFOOutcome:
    """Iterative palm-finger optimisation (Algorithm 1) of one fit with fixed correspondences.

    Alternates the palm step (eq. 10, :func:`palm_step`) and the finger step (eq. 11-13,
    :func:`finger_step`); an alternation that would raise E is undone and ends IPFO, as does a
    decrease of E per pair below ``config.ipfo_tolerance`` or ``config.max_ipfo_iterations``
    alternations. The fingers stay put with ``config.lock_fingers`` or a gripper without joints.
    ISF runs it once per iteration (:func:`fit`, Algorithm 2; the planner around ISF is
    :func:`isf.planning.planner.plan`, Algorithm 3). The compiled engine's IPFO
    (``isf.fitting._ipfo_kernel``) is checked against this one through whole fits (:func:`fit`
    against :func:`isf.fit`).

    Args:
        pairs: the matched pairs of one fit (``segments`` a single group).
        T: palm pose ``T_object_gripper``, (4, 4).
        q: joints, (n_joints,).
        links: contact-link kinematics at ``q`` (arrays (L, ...), :meth:`Gripper.link_kinematics`).
        config: parameters.
    """
    gripper = pairs.gripper
    move_fingers = gripper.n_joints > 0 and not config.lock_fingers
    threshold = config.ipfo_tolerance * len(pairs)  # Delta e, for this many pairs
    alpha = config.normal_weight
    E = _error(pairs, T, links, alpha)  # Line 2: R* = I, t* = 0, dd* = 0 (the current state)
    errors = []
    for _ in range(config.max_ipfo_iterations):  # Line 3: while e_p - E(R*, t*, dd*) > Delta e
        e_p = E  # Line 4
        points, normals, _ = _evaluate(pairs, links)
        object_points, object_normals = pairs.to_object(T[None], points, normals)
        T_new = palm_step(object_points, object_normals, pairs.targets, pairs.target_normals,
                          alpha, config.max_rotation_step) @ T  # Line 5: eq. 10
        q_new, links_new = q, links
        if move_fingers:  # Line 6: eq. 11-13
            q_new = finger_step(pairs, T_new, q, links, config)
            if np.any(q_new != q):
                links_new = _kinematics(gripper, q_new)
        E_new = _error(pairs, T_new, links_new, alpha)
        if E_new > e_p:  # the alternation would raise E: undo it
            break
        T, q, links, E = T_new, q_new, links_new, E_new
        errors.append(E)
        if e_p - E <= threshold:  # Line 3: E decreased by Delta e or less
            break
    return IPFOOutcome(T, q, links, E, tuple(errors))  # Line 8


def palm_step(points: np.ndarray, normals: np.ndarray, targets: np.ndarray,
              target_normals: np.ndarray, normal_weight: float, max_rotation: float) -> np.ndarray:
    """The palm step of IPFO (eq. 10): ``T_delta`` (4, 4) to apply on the left of the palm pose.

    Least squares ``x = (A^T A)^-1 A^T b`` over the twist ``x = [r, u]`` with point-to-plane
    rows ``a_i = [(p_i - c) x n^q_i, n^q_i]``, ``b_i = (q_i - p_i)^T n^q_i`` (eq. 5, about the
    contact centroid ``c``) and normal rows ``[alpha n^p_i x n^q_i, 0]``,
    ``-alpha ((n^p_i)^T n^q_i + 1)`` (eq. 8), with ``R ~ I + [r]x``; a ridge of
    ``PALM_RIDGE * trace`` holds the directions the surfaces leave free. A rotation beyond
    ``max_rotation`` (radians) is scaled down with its translation; ``R = exp([r]x)``.

    Args:
        points, normals: contact points ``p_i`` (metres) and normals ``n^p_i``, object frame,
            (K, 3).
        targets, target_normals: matched object points ``q_i`` and normals ``n^q_i``, (K, 3).
        normal_weight: ``alpha``, metres.
        max_rotation: radians.
    """
    H, g, centre = palm_system(points, normals, targets, target_normals, normal_weight)
    x = np.linalg.solve(H + PALM_RIDGE * max(np.trace(H), 1e-300) * np.eye(6), g)  # eq. 10
    x *= min(1.0, max_rotation / max(np.linalg.norm(x[:3]), 1e-300))
    R = _exp_so3(x[:3])
    T_delta = np.eye(4)
    T_delta[:3, :3], T_delta[:3, 3] = R, centre + x[3:] - R @ centre
    return T_delta


def palm_system(points: np.ndarray, normals: np.ndarray, targets: np.ndarray,
                 target_normals: np.ndarray, normal_weight: float):
    """The palm step's normal equations (eq. 10): ``H = A^T A`` (6, 6), ``g = A^T b`` (6,) over
    the twist ``[r, u]`` about the contact centroid ``centre`` (3,) (arguments as
    :func:`palm_step` takes them)."""
    centre = points.mean(axis=0)
    A = np.c_[np.cross(points - centre, target_normals), target_normals]  # eq. 5a
    b = np.einsum("ij,ij->i", targets - points, target_normals)  # eq. 5b
    if normal_weight > 0.0:  # the rows of E_n (eq. 8), stacked as in eq. 10
        rows = np.c_[normal_weight * np.cross(normals, target_normals), np.zeros((len(b), 3))]
        A = np.r_[A, rows]
        b = np.r_[b, -normal_weight * (np.einsum("ij,ij->i", normals, target_normals) + 1.0)]
    return A.T @ A, A.T @ b, centre


def finger_step(pairs: PairBatch, T: np.ndarray, q: np.ndarray, links: LinkKinematics,
                config: FitConfig) -> np.ndarray:
    """The finger step of IPFO (eq. 11-13) with the palm at ``T`` (4, 4): the new joints
    (n_joints,).

    Minimises the linearised error ``||A dq - b||^2 + lambda ||dq||^2`` (rows of
    :meth:`PairBatch.finger_rows`, ``lambda = config.finger_damping`` plus a ridge of
    ``FINGER_RIDGE * trace``) over the joint step ``dq`` within the joint limits and, for revolute
    joints, ``+- config.max_revolute_step``; for one joint that is eq. 12-13 (the minimiser,
    clipped), for more :func:`box_qp`.
    """
    gripper = pairs.gripper
    points, normals, offsets = _evaluate(pairs, links)
    AtA, Atb = pairs.finger_system(T[None], points, normals, offsets, _batch(links),
                                   config.normal_weight)
    H = AtA[0] + config.finger_damping * np.eye(gripper.n_joints)
    H += FINGER_RIDGE * max(np.trace(H), 1e-300) * np.eye(gripper.n_joints)
    step = np.where(gripper.revolute, config.max_revolute_step, np.inf)
    lower = np.minimum(np.maximum(gripper.lower - q, -step), 0.0)  # eq. 11b
    upper = np.maximum(np.minimum(gripper.upper - q, step), 0.0)
    dq = box_qp(H, Atb[0], lower, upper)  # eq. 12-13
    return np.clip(q + dq, gripper.lower, gripper.upper)


def box_qp(H: np.ndarray, g: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``argmin 1/2 x^T H x - g^T x`` subject to ``lower <= x <= upper`` (H (n, n) positive
    definite), by enumerating which coordinates sit at which bound, fewest first, until one
    meets the KKT conditions (free coordinates within their bounds, multipliers of the right
    sign). One coordinate is eq. 12-13: the unconstrained minimiser clipped."""
    n = len(g)
    if n == 1:
        return np.clip(g / H[0, 0], lower, upper)
    tolerance = 1e-12 * (1.0 + np.abs(g).max() + np.abs(H).max())
    for n_bound in range(n + 1):
        for bound in itertools.combinations(range(n), n_bound):
            for sides in itertools.product((lower, upper), repeat=n_bound):
                x = np.zeros(n)
                for i, side in zip(bound, sides):
                    x[i] = side[i]
                free = np.setdiff1d(np.arange(n), bound)
                if len(free):
                    x[free] = np.linalg.solve(H[np.ix_(free, free)],
                                              g[free] - H[np.ix_(free, bound)] @ x[list(bound)])
                r = H @ x - g  # the gradient: the multipliers of the bound coordinates
                inside = np.all(x[free] >= lower[free] - tolerance) and np.all(
                    x[free] <= upper[free] + tolerance)
                signs = all(r[i] >= -tolerance if side is lower else r[i] <= tolerance
                            for i, side in zip(bound, sides))
                if inside and signs:
                    return np.clip(x, lower, upper)
    raise ArithmeticError("no active set meets the KKT conditions (is H positive definite?)")


def correspondences(gripper: Gripper, obj: ObjectSurface, search: cKDTree, rows: np.ndarray,
                    points: np.ndarray, normals: np.ndarray, config: FitConfig) -> Pairs:
    """Correspondence matching (Algorithm 2, lines 8-9): each contact point's nearest object
    point, then the filters of ``config``.

    A pair is kept when its distance is within ``max(outlier_factor * median, outlier_floor)``
    of its group (its contact surface, or the whole fit for ``outlier_scope="fit"``; the median
    over every queried point of the group), and, unless ``max_normal_angle >= pi``, the contact
    normal is within that angle of the reversed object normal; with ``reject_duplicates`` only
    the nearest pair of those sharing an object point stays (the first of equally near ones).

    Args:
        gripper, obj: the gripper and the object surface.
        search: a k-d tree of ``obj.points``.
        rows: gripper point indices queried, (M,).
        points, normals: those contact points and normals, object frame, (M, 3).
        config: the filters' parameters.
    """
    _, targets = search.query(points)  # S^o = NN(S^f)
    distances = np.sqrt(np.sum((points - obj.points[targets]) ** 2, axis=1))
    compatible = np.ones(len(rows), dtype=bool)
    if config.max_normal_angle < np.pi:
        cosines = np.einsum("ij,ij->i", normals, obj.normals[targets])
        compatible = cosines <= -np.cos(config.max_normal_angle)
    if config.outlier_scope == "surface":
        groups = gripper.point_surface[rows]
    else:
        groups = np.zeros(len(rows), dtype=int)
    keep = np.zeros(len(rows), dtype=bool)
    for group in np.unique(groups):
        members = groups == group
        limit = max(config.outlier_factor * np.median(distances[members]), config.outlier_floor)
        keep[members] = (distances[members] <= limit) & compatible[members]
    if config.reject_duplicates:
        nearest: dict[int, int] = {}
        for i in np.flatnonzero(keep).tolist():
            j = nearest.setdefault(int(targets[i]), i)
            if j != i:
                loser = i if distances[i] >= distances[j] else j
                keep[loser] = False
                nearest[int(targets[i])] = i + j - loser
    kept = np.flatnonzero(keep)
    return Pairs(rows[kept], targets[kept], distances)


def _kinematics(gripper: Gripper, q: np.ndarray) -> LinkKinematics:
    """Contact-link kinematics at joints ``q`` (n_joints,) from Pinocchio (not the engine's
    compiled chain): poses (L, 3, 3), (L, 3) and LOCAL_WORLD_ALIGNED Jacobians (L, 3, n_joints),
    gripper frame."""
    model = gripper.model
    data = model.createData()
    pin.computeJointJacobians(model, data, np.asarray(q, dtype=float))
    pin.updateFramePlacements(model, data)
    frames = gripper.link_frames.tolist()
    poses = np.array([data.oMf[f].homogeneous for f in frames])
    J = np.zeros((len(frames), 6, model.nv))
    for k, f in enumerate(frames):
        if model.nv:
            J[k] = pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)
    return LinkKinematics(poses[:, :3, :3], poses[:, :3, 3], J[:, :3], J[:, 3:])


def _batch(links: LinkKinematics) -> LinkKinematics:
    """One fit's kinematics with a leading fit axis of length 1 (as :class:`PairBatch` takes it)."""
    return LinkKinematics(*(a[None] for a in links))


def _evaluate(pairs: PairBatch, links: LinkKinematics):
    """One fit's contact points, normals and offsets from their link origins, gripper frame."""
    return pairs.evaluate(_batch(links))


def _error(pairs: PairBatch, T: np.ndarray, links: LinkKinematics, alpha: float) -> float:
    """``E = E_p + alpha^2 E_n`` (eq. 7-9) of one fit's pairs, m^2."""
    points, normals, _ = _evaluate(pairs, links)
    return float(pairs.errors(T[None], points, normals, alpha)[0])


def _place(gripper: Gripper, T: np.ndarray, links: LinkKinematics, rows: np.ndarray):
    """Contact points ``rows`` (M,) of the gripper at palm pose ``T`` and link kinematics ``links``:
    points and normals in the object frame, each (M, 3)."""
    link = gripper.point_link[rows]
    R = T[:3, :3] @ links.rotations[link]
    points = np.einsum("kij,kj->ki", R, gripper.points_link[rows]) + (
        links.positions[link] @ T[:3, :3].T + T[:3, 3])
    return points, np.einsum("kij,kj->ki", R, gripper.normals_link[rows])


def _exp_so3(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula ``I + sin(t)/t [r]x + (1 - cos(t))/t^2 [r]x^2`` (3, 3), ``t = |r|``."""
    theta = np.linalg.norm(r)
    K = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    if theta < 1e-9:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * K @ K


def _result(gripper: Gripper, obj: ObjectSurface, search: cKDTree, config: FitConfig,
            T: np.ndarray, q: np.ndarray, status: FitStatus, records: list[IterationRecord],
            started: float) -> FitResult:
    """The :class:`FitResult` of a final state: every contact point matched afresh (with the
    filters of :func:`correspondences`, without ``min_pairs``) and scored."""
    links = _kinematics(gripper, q)
    rows = np.arange(gripper.n_points)
    points, normals = _place(gripper, T, links, rows)
    pairs = correspondences(gripper, obj, search, rows, points, normals, config)
    targets, target_normals = obj.points[pairs.targets], obj.normals[pairs.targets]
    d = np.einsum("kj,kj->k", points[pairs.rows] - targets, target_normals)
    c = np.einsum("kj,kj->k", normals[pairs.rows], target_normals) + 1.0
    K = len(pairs.rows)
    touching = pairs.distances <= config.contact_distance
    surface_contact = {s.name: float(touching[gripper.point_surface == k].mean())
                       for k, s in enumerate(gripper.surfaces)}
    return FitResult(
        T_object_gripper=T, q=q, joints=gripper.joints(q),
        mean_distance=float(np.abs(d).mean()) if K else np.inf,
        normal_misalignment=float(np.arccos(np.clip(1.0 - c, -1.0, 1.0)).mean()) if K else np.inf,
        error=float(np.sum(d * d + config.normal_weight**2 * c * c)) if K else np.inf,
        n_pairs=K, contact_points=points[pairs.rows], object_points=targets,
        surface_contact=surface_contact, iterations=max(0, len(records) - 1), status=status,
        history=History.from_records(records, gripper.n_joints),
        time=time.perf_counter() - started)


def _rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise ``R_k v_k`` for R (K, 3, 3) and v (K, 3), (K, 3)."""
    return np.einsum("kij,kj->ki", R, v)


class PairBatch:
    """Matched (contact point, object point) pairs of B fits, stored fit after fit.

    Args:
        gripper: the gripper.
        segments: the fit of each pair (pairs grouped by fit).
        point_index: indices of the matched contact points into the gripper's points, (K,).
        targets: matched object points, object frame, (K, 3), metres.
        target_normals: object normals at the targets, (K, 3).
    """

    def __init__(self, gripper: Gripper, segments: Segments, point_index, targets, target_normals):
        self.gripper = gripper
        self.segments = segments
        self.point_index = np.asarray(point_index)
        self.targets = np.asarray(targets, dtype=float)
        self.target_normals = np.asarray(target_normals, dtype=float)
        self.link = gripper.point_link[self.point_index]
        """Contact link of each pair (index into ``gripper.contact_links``), (K,)."""
        self.points_link = gripper.points_link[self.point_index]
        """Contact points in their link frames, (K, 3), metres."""
        self.normals_link = gripper.normals_link[self.point_index]
        """Contact normals in their link frames, (K, 3)."""

    def __len__(self) -> int:
        return len(self.point_index)

    def evaluate(self, links: LinkKinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact points, normals and offsets from their link origins, gripper frame, each (K, 3).

        Args:
            links: kinematics of the B fits (arrays with a leading fit axis, see
                :meth:`Gripper.link_kinematics_many`).
        """
        fit, link = self.segments.ids, self.link
        R = links.rotations[fit, link]
        offsets = _rotate(R, self.points_link)
        return offsets + links.positions[fit, link], _rotate(R, self.normals_link), offsets

    def to_object(self, T: np.ndarray, points: np.ndarray,
                  normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gripper-frame points and normals (K, 3) moved by each pair's palm pose ``T``
        (B, 4, 4)."""
        Tk = T[self.segments.ids]
        R = Tk[:, :3, :3]
        return _rotate(R, points) + Tk[:, :3, 3], _rotate(R, normals)

    def residuals(self, T: np.ndarray, points: np.ndarray,
                  normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point-to-plane distances (K,) in metres and normal terms ``(R n^p)^T n^q + 1`` (K,).

        Args:
            T: palm poses ``T_object_gripper`` of the B fits, (B, 4, 4).
            points, normals: gripper-frame contact points and normals, (K, 3).
        """
        p, n = self.to_object(T, points, normals)
        d = np.einsum("kj,kj->k", p - self.targets, self.target_normals)
        c = np.einsum("kj,kj->k", n, self.target_normals) + 1.0
        return d, c

    def errors(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray,
               normal_weight: float) -> np.ndarray:
        """``E = E_p + alpha^2 E_n`` (eq. 7-9) of each fit, (B,), m^2."""
        d, c = self.residuals(T, points, normals)
        return self.segments.sum(d * d + normal_weight**2 * (c * c))

    def finger_rows(self, T, points, normals, offsets, links: LinkKinematics, normal_weight: float):
        """Rows of the finger least squares: ``A`` (K, n), ``b`` (K,), and the normal rows
        ``An`` (K, n), ``bn`` (K,) (None when alpha is 0 or no joint turns a link).

        With the palm at ``T`` fixed, moving the joints by ``dq`` moves point ``i``
        (on link ``k``, offset ``r_i`` from its origin) by ``R (Jv_k + Jw_k x r_i) dq``,
        so its point-to-plane row is ``m_i^T Jv_k + (r_i x m_i)^T Jw_k`` with
        ``m_i = R^T n^q_i``, and its right-hand side ``-(R p_i + t - q_i)^T n^q_i``.
        Joints that turn links add alpha-weighted normal rows
        ``alpha (n_i x m_i)^T Jw_k``, ``-alpha (n_i^T m_i + 1)``.
        """
        fit, link = self.segments.ids, self.link
        R = T[fit, :3, :3]
        m = np.einsum("kji,kj->ki", R, self.target_normals)
        Jv, Jw = links.J_linear[fit, link], links.J_angular[fit, link]
        A = np.einsum("kj,kjn->kn", m, Jv) + np.einsum("kj,kjn->kn", cross(offsets, m), Jw)
        b = -self.residuals(T, points, normals)[0]
        if normal_weight > 0.0 and np.any(links.J_angular):
            An = normal_weight * np.einsum("kj,kjn->kn", cross(normals, m), Jw)
            bn = -normal_weight * (np.einsum("kj,kj->k", normals, m) + 1.0)
            return A, b, An, bn
        return A, b, None, None

    def finger_system(self, T, points, normals, offsets, links, normal_weight):
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b``
        (B, n)."""
        A, b, An, bn = self.finger_rows(T, points, normals, offsets, links, normal_weight)
        AtA = self.segments.sum(A[:, :, None] * A[:, None, :])
        Atb = self.segments.sum(A * b[:, None])
        if An is not None:
            AtA += self.segments.sum(An[:, :, None] * An[:, None, :])
            Atb += self.segments.sum(An * bn[:, None])
        return AtA, Atb
