"""Compiled arithmetic of the moment form of IPFO (see :mod:`isf.fitting._moments` for the maths).

Each kernel loops over link groups (one contact link of one fit; group ``g = b * L + l``)
with small fixed-size sums, so that an IPFO alternation is three calls (in numpy the same sums
are about 40 array calls, whose call overhead, not their arithmetic, would dominate a fit).
Groups without pairs (``count[g] == 0``) have zero moments and are skipped. Every kernel is
float64 throughout and is compiled once (numba, cached on disk), whatever the gripper.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..compiled.kernels import kernel
from ..compiled.leaf import leaf

__all__ = ["GroupMoments", "fit_errors", "finger_systems", "group_moments", "link_poses",
           "palm_motion", "palm_motions", "palm_systems", "palm_updates", "place",
           "points_in_object", "solve_small"]


class GroupMoments(NamedTuple):
    """The moments of B fits' pairs per link group (:func:`group_moments`; G = B * L groups),
    float64, taken about each fit's ``origin``.

    Attributes:
        origin: each fit's target centroid, object frame, (B, 3), m.
        fit_count: each fit's pairs, (B,).
        M: sums of ``y y^T``, (G, 12, 12).
        N: sums of ``u u^T``, (G, 9, 9).
        v: sums of ``beta y``, (G, 12), m.
        beta2: sums of ``beta^2``, (G,), m^2.
        w: sums of ``u``, (G, 9).
        s: sums of ``[x, 1]``, (G, 4), m.
        count: each group's pairs, (G,).
    """

    origin: np.ndarray
    fit_count: np.ndarray
    M: np.ndarray
    N: np.ndarray
    v: np.ndarray
    beta2: np.ndarray
    w: np.ndarray
    s: np.ndarray
    count: np.ndarray


class _PalmMoments(NamedTuple):
    """The fields of :class:`GroupMoments` that the palm step reads."""

    origin: np.ndarray
    fit_count: np.ndarray
    M: np.ndarray
    N: np.ndarray
    v: np.ndarray
    w: np.ndarray
    s: np.ndarray
    count: np.ndarray


@kernel(inline=True)
def _add_outer(A, r, c, a0, a1, a2, b0, b1, b2):
    """``A[r:r+3, c:c+3] += a b^T`` for 3-vectors ``a``, ``b`` given as scalars."""
    A[r, c] += a0 * b0
    A[r, c + 1] += a0 * b1
    A[r, c + 2] += a0 * b2
    A[r + 1, c] += a1 * b0
    A[r + 1, c + 1] += a1 * b1
    A[r + 1, c + 2] += a1 * b2
    A[r + 2, c] += a2 * b0
    A[r + 2, c + 1] += a2 * b1
    A[r + 2, c + 2] += a2 * b2


@kernel(inline=True)
def _add_self_outer(A, r, a0, a1, a2):
    """The upper triangle of ``A[r:r+3, r:r+3] += a a^T``."""
    A[r, r] += a0 * a0
    A[r, r + 1] += a0 * a1
    A[r, r + 2] += a0 * a2
    A[r + 1, r + 1] += a1 * a1
    A[r + 1, r + 2] += a1 * a2
    A[r + 2, r + 2] += a2 * a2


@kernel(inline=True)
def _add_scaled(a, r, scale, b0, b1, b2):
    """``a[r:r+3] += scale * b``."""
    a[r] += scale * b0
    a[r + 1] += scale * b1
    a[r + 2] += scale * b2


@kernel(inline=True)
def _add_gram(A, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """The upper triangle of ``A[:9, :9] += z z^T`` for ``z = [a, b, c]`` (three 3-vectors), in
    3 x 3 blocks."""
    _add_self_outer(A, 0, a0, a1, a2)
    _add_outer(A, 0, 3, a0, a1, a2, b0, b1, b2)
    _add_outer(A, 0, 6, a0, a1, a2, c0, c1, c2)
    _add_self_outer(A, 3, b0, b1, b2)
    _add_outer(A, 3, 6, b0, b1, b2, c0, c1, c2)
    _add_self_outer(A, 6, c0, c1, c2)


@kernel(inline=True)
def _add_scaled_three(a, scale, b0, b1, b2, c0, c1, c2, d0, d1, d2):
    """``a[:9] += scale * [b, c, d]`` for three 3-vectors."""
    _add_scaled(a, 0, scale, b0, b1, b2)
    _add_scaled(a, 3, scale, c0, c1, c2)
    _add_scaled(a, 6, scale, d0, d1, d2)


@kernel
def group_moments(fit, link, points_link, normals_link, targets, target_normals, n_fits, n_links):
    """Per-group moments of matched pairs.

    Args:
        fit, link: fit and contact link of each pair, (K,) integers.
        points_link, normals_link: link-frame contact points ``x_i`` (metres) and normals, (K, 3).
        targets, target_normals: object points ``q_i`` (metres) and normals ``n^q_i``, (K, 3).
        n_fits, n_links: B and L.

    Returns:
        The :class:`GroupMoments`: ``origin`` (B, 3): each fit's target centroid (object frame,
        metres), ``fit_count`` (B,), and per group ``M`` (G, 12, 12), ``N`` (G, 9, 9), ``v``
        (G, 12), ``beta2`` (G,), ``w`` (G, 9), ``s`` (G, 4), ``count`` (G,) with ``G = B * L``;
        the sums are taken about ``origin``.

    A pair adds ``y y^T`` to ``M`` and ``beta y`` to ``v`` for ``y = [x_0 n, x_1 n, x_2 n, n]``
    (``n = n^q_i``, ``beta = (q_i - origin) . n``), and ``u u^T`` to ``N``, ``u`` to ``w`` for
    ``u = [m_0 n, m_1 n, m_2 n]`` (``m`` the link-frame normal), in 3 x 3 blocks of the upper
    triangles, every entry a sum over the pairs in their order from +0 (the lower triangles
    are copied from the upper at the end). Each component of ``y`` and ``u`` is computed once
    per pair and kept in a register rather than looped over entry by entry (the same sums).
    """
    n_groups = n_fits * n_links
    origin = np.zeros((n_fits, 3))
    fit_count = np.zeros(n_fits)
    for k in range(len(fit)):
        b = fit[k]
        fit_count[b] += 1.0
        for j in range(3):
            origin[b, j] += targets[k, j]
    for b in range(n_fits):
        for j in range(3):
            origin[b, j] /= max(fit_count[b], 1.0)
    M = np.zeros((n_groups, 12, 12))
    N = np.zeros((n_groups, 9, 9))
    v = np.zeros((n_groups, 12))
    beta2 = np.zeros(n_groups)
    w = np.zeros((n_groups, 9))
    s = np.zeros((n_groups, 4))
    count = np.zeros(n_groups)
    for k in range(len(fit)):
        b = fit[k]
        g = b * n_links + link[k]
        beta = 0.0
        for j in range(3):
            beta += (targets[k, j] - origin[b, j]) * target_normals[k, j]
        x0, x1, x2 = points_link[k, 0], points_link[k, 1], points_link[k, 2]
        m0, m1, m2 = normals_link[k, 0], normals_link[k, 1], normals_link[k, 2]
        n0, n1, n2 = target_normals[k, 0], target_normals[k, 1], target_normals[k, 2]
        a0, a1, a2 = x0 * n0, x0 * n1, x0 * n2  # y = [a, b, c, n]
        b0, b1, b2 = x1 * n0, x1 * n1, x1 * n2
        c0, c1, c2 = x2 * n0, x2 * n1, x2 * n2
        Mg, vg = M[g], v[g]
        _add_gram(Mg, a0, a1, a2, b0, b1, b2, c0, c1, c2)
        _add_outer(Mg, 0, 9, a0, a1, a2, n0, n1, n2)
        _add_outer(Mg, 3, 9, b0, b1, b2, n0, n1, n2)
        _add_outer(Mg, 6, 9, c0, c1, c2, n0, n1, n2)
        _add_self_outer(Mg, 9, n0, n1, n2)
        _add_scaled_three(vg, beta, a0, a1, a2, b0, b1, b2, c0, c1, c2)
        _add_scaled(vg, 9, beta, n0, n1, n2)
        d0, d1, d2 = m0 * n0, m0 * n1, m0 * n2  # u = [d, e, f]
        e0, e1, e2 = m1 * n0, m1 * n1, m1 * n2
        f0, f1, f2 = m2 * n0, m2 * n1, m2 * n2
        _add_gram(N[g], d0, d1, d2, e0, e1, e2, f0, f1, f2)
        _add_scaled_three(w[g], 1.0, d0, d1, d2, e0, e1, e2, f0, f1, f2)
        beta2[g] += beta * beta
        s[g, 0] += x0
        s[g, 1] += x1
        s[g, 2] += x2
        s[g, 3] += 1.0
        count[g] += 1.0
    for g in range(n_groups):
        for i in range(12):
            for j in range(i):
                M[g, i, j] = M[g, j, i]
        for i in range(9):
            for j in range(i):
                N[g, i, j] = N[g, j, i]
    return GroupMoments(origin, fit_count, M, N, v, beta2, w, s, count)


@kernel
def link_poses(T, rotations, positions, A, a):
    """Every contact link's pose in the object frame, in place: ``A[l] = R_palm R_link`` (L, 3, 3)
    and the origins ``a[l]`` (L, 3), for one fit (``T`` (4, 4), ``rotations`` (L, 3, 3),
    ``positions`` (L, 3))."""
    no_origin = np.zeros(3)
    for l in range(len(rotations)):
        _group_pose(T, rotations[l], positions[l], no_origin, A[l], a[l])


@leaf
def _group_pose(T, rotation, position, origin, A, a):
    """``A = R_palm R_link`` (3, 3) and the link origin ``a`` (3,) relative to ``origin``, in
    place."""
    for i in range(3):
        for j in range(3):
            A[i, j] = T[i, 0] * rotation[0, j] + T[i, 1] * rotation[1, j] + T[i, 2] * rotation[2, j]
        a[i] = T[i, 0] * position[0] + T[i, 1] * position[1] + T[i, 2] * position[2] + T[i, 3] - origin[i]


@leaf
def _vec_pose(A, a, P):
    """``P = vec([A | a]^T)`` (12,), in place: ``P[3 i + j] = A[j, i]`` and ``P[9 + j] = a[j]``."""
    for i in range(3):
        for j in range(3):
            P[3 * i + j] = A[j, i]
        P[9 + i] = a[i]


@leaf
def _residual(M, v, P, out):
    """``out = v - M P`` (12,), in place."""
    for i in range(12):
        acc = v[i]
        for j in range(12):
            acc -= M[i, j] * P[j]
        out[i] = acc


@leaf
def _add_sandwich(X, M, rows, cols, weight, out, XM, used):
    """``out += weight * X[:, :cols] M[:cols, :cols] X[:, :cols]^T`` for ``X`` (rows, >= cols).

    Rows of ``X`` that are zero in its first ``cols`` columns are left out of the sums (a
    finger's joints do not move the other fingers' links): their terms would add +0 to sums
    that start at +0, so the result is that of the full sums bit for bit. ``XM`` (rows, cols)
    and ``used`` (rows,): scratch; ``used`` is left marking the rows that entered.
    """
    for i in range(rows):
        used[i] = False
        for k in range(cols):
            if X[i, k] != 0.0:
                used[i] = True
                break
    for i in range(rows):
        if not used[i]:
            continue
        for j in range(cols):
            acc = 0.0
            for k in range(cols):
                acc += X[i, k] * M[k, j]
            XM[i, j] = acc
    for i in range(rows):
        if not used[i]:
            continue
        for j in range(rows):
            if not used[j]:
                continue
            acc = 0.0
            for k in range(cols):
                acc += XM[i, k] * X[j, k]
            out[i, j] += weight * acc


@kernel(inline=True)
def _lever_dot(G, i, M, j, cols):
    """``sum_k G[i, k] M[k, j]`` over the columns ``k < cols`` (9 or 12) where row ``i`` (0-2)
    of the palm's lever matrix may be non-zero, in ascending order from +0: row ``i`` holds
    ``[c]_x`` of four columns ``c``, whose diagonal is zero."""
    if i == 0:
        s = 0.0 + G[0, 1] * M[1, j] + G[0, 2] * M[2, j] + G[0, 4] * M[4, j] + G[0, 5] * M[5, j] \
            + G[0, 7] * M[7, j] + G[0, 8] * M[8, j]
        if cols > 9:
            s = s + G[0, 10] * M[10, j] + G[0, 11] * M[11, j]
    elif i == 1:
        s = 0.0 + G[1, 0] * M[0, j] + G[1, 2] * M[2, j] + G[1, 3] * M[3, j] + G[1, 5] * M[5, j] \
            + G[1, 6] * M[6, j] + G[1, 8] * M[8, j]
        if cols > 9:
            s = s + G[1, 9] * M[9, j] + G[1, 11] * M[11, j]
    else:
        s = 0.0 + G[2, 0] * M[0, j] + G[2, 1] * M[1, j] + G[2, 3] * M[3, j] + G[2, 4] * M[4, j] \
            + G[2, 6] * M[6, j] + G[2, 7] * M[7, j]
        if cols > 9:
            s = s + G[2, 9] * M[9, j] + G[2, 10] * M[10, j]
    return s


@leaf
def _add_palm_sandwich(G, M, cols, weight, out, GM):
    """``out += weight * G[:r, :cols] M G[:r, :cols]^T`` for the palm's lever matrix ``G`` (6, 12)
    (rows 0-2: cross-product blocks, rows 3-5: ``[0 | I]``), ``r = 6`` for ``cols = 12`` and
    ``r = 3`` for ``cols = 9``: :func:`_add_sandwich` without the terms that are zero by the
    structure of ``G`` (a zero term leaves a sum from +0 unchanged: the same result bit for
    bit). ``GM`` (6, 12): scratch."""
    rows = 6 if cols == 12 else 3
    for j in range(cols):
        for i in range(3):
            GM[i, j] = _lever_dot(G, i, M, j, cols)
        for i in range(3, rows):
            GM[i, j] = 0.0 + M[6 + i, j]
    GMt = GM.T
    for a in range(rows):
        for b in range(3):
            out[a, b] += weight * _lever_dot(G, b, GMt, a, cols)
        for b in range(3, rows):
            out[a, b] += weight * (0.0 + GM[a, 6 + b])


@leaf
def _normal_residual(N, P, w, out):
    """``out = N P[:9] + w`` (9,), in place."""
    for i in range(9):
        acc = w[i]
        for j in range(9):
            acc += N[i, j] * P[j]
        out[i] = acc


@kernel
def fit_errors(T, rotations, positions, origin, M, N, v, beta2, w, count, alpha2):
    """``E = E_p + alpha^2 E_n`` of each fit, (B,), m^2.

    Args:
        T: palm poses ``T_object_gripper``, (B, 4, 4).
        rotations, positions: contact-link poses in the gripper frame, (B, L, 3, 3), (B, L, 3).
        origin, M, N, v, beta2, w, count: from :func:`group_moments`.
        alpha2: ``alpha^2``, m^2.
    """
    n_fits, n_links = rotations.shape[0], rotations.shape[1]
    E = np.zeros(n_fits)
    A, a, P = np.empty((3, 3)), np.empty(3), np.empty(12)
    for b in range(n_fits):
        total = 0.0
        for l in range(n_links):
            g = b * n_links + l
            if count[g] == 0.0:
                continue
            _group_pose(T[b], rotations[b, l], positions[b, l], origin[b], A, a)
            _vec_pose(A, a, P)
            Ep, En = beta2[g], count[g]
            for i in range(12):
                MP = 0.0
                for j in range(12):
                    MP += M[g, i, j] * P[j]
                Ep += P[i] * (MP - 2.0 * v[g, i])
            for i in range(9):
                NP = 0.0
                for j in range(9):
                    NP += N[g, i, j] * P[j]
                En += P[i] * (NP + 2.0 * w[g, i])
            total += Ep + alpha2 * En
        E[b] = total
    return E


@kernel
def _palm_system(b, T, rotations, positions, sums, alpha2, H, grad, centre):
    """Palm normal equations of fit ``b`` about its contact centroid, into ``H`` (6, 6),
    ``grad`` (6,) and ``centre`` (3,) (object frame, relative to ``origin[b]``); ``sums``:
    :class:`_PalmMoments`."""
    origin, fit_count, M, N, v, w, s, count = (sums.origin, sums.fit_count, sums.M, sums.N,
                                               sums.v, sums.w, sums.s, sums.count)
    n_links = rotations.shape[1]
    A, a = np.empty((n_links, 3, 3)), np.empty((n_links, 3))
    for j in range(3):
        centre[j] = 0.0
    for l in range(n_links):
        g = b * n_links + l
        _group_pose(T[b], rotations[b, l], positions[b, l], origin[b], A[l], a[l])
        for i in range(3):
            centre[i] += (A[l, i, 0] * s[g, 0] + A[l, i, 1] * s[g, 1] + A[l, i, 2] * s[g, 2]
                          + a[l, i] * s[g, 3])
    for j in range(3):
        centre[j] /= fit_count[b]
    H[:] = 0.0
    grad[:] = 0.0
    G, GM = np.zeros((6, 12)), np.empty((6, 12))
    P, r, rn = np.empty(12), np.empty(12), np.empty(9)
    for i in range(3):
        G[3 + i, 9 + i] = 1.0
    col = np.empty(3)
    for l in range(n_links):
        g = b * n_links + l
        if count[g] == 0.0:
            continue
        _vec_pose(A[l], a[l], P)
        _residual(M[g], v[g], P, r)
        for j in range(4):  # G[:3, 3j:3j+3] = [c_j]_x with c = columns of [A | a - centre]
            for i in range(3):
                col[i] = A[l, i, j] if j < 3 else a[l, i] - centre[i]
            G[0, 3 * j + 1], G[0, 3 * j + 2] = -col[2], col[1]
            G[1, 3 * j], G[1, 3 * j + 2] = col[2], -col[0]
            G[2, 3 * j], G[2, 3 * j + 1] = -col[1], col[0]
        _add_palm_sandwich(G, M[g], 12, 1.0, H, GM)
        for i in range(6):
            acc = 0.0
            for j in range(12):
                acc += G[i, j] * r[j]
            grad[i] += acc
        if alpha2 > 0.0:
            _add_palm_sandwich(G, N[g], 9, alpha2, H, GM)
            _normal_residual(N[g], P, w[g], rn)
            for i in range(3):
                acc = 0.0
                for j in range(9):
                    acc += G[i, j] * rn[j]
                grad[i] -= alpha2 * acc


@kernel
def palm_systems(T, rotations, positions, origin, fit_count, M, N, v, w, s, count, alpha2):
    """Palm normal equations of every fit: ``H`` (B, 6, 6), ``g`` (B, 6) for the twist
    ``[r, u]`` about each fit's contact centroid, and the centroids (B, 3), object frame."""
    n_fits = rotations.shape[0]
    H, grad, centre = np.empty((n_fits, 6, 6)), np.empty((n_fits, 6)), np.empty((n_fits, 3))
    sums = _PalmMoments(origin, fit_count, M, N, v, w, s, count)
    for b in range(n_fits):
        _palm_system(b, T, rotations, positions, sums, alpha2, H[b], grad[b], centre[b])
        for j in range(3):
            centre[b, j] += origin[b, j]
    return H, grad, centre


@leaf
def solve_small(LU, y, x):
    """Solve ``H x = rhs`` for a small square ``H`` (n, n) into ``x`` (n,): Gaussian elimination
    with partial pivoting (LAPACK's ``gesv`` method) in place, on ``LU = H`` and ``y = rhs``,
    which it overwrites (pass copies to keep them)."""
    n = len(y)
    for k in range(n):
        pivot = k
        for i in range(k + 1, n):
            if abs(LU[i, k]) > abs(LU[pivot, k]):
                pivot = i
        if pivot != k:
            for j in range(n):
                LU[k, j], LU[pivot, j] = LU[pivot, j], LU[k, j]
            y[k], y[pivot] = y[pivot], y[k]
        for i in range(k + 1, n):
            factor = LU[i, k] / LU[k, k]
            for j in range(k + 1, n):
                LU[i, j] -= factor * LU[k, j]
            y[i] -= factor * y[k]
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for j in range(i + 1, n):
            acc -= LU[i, j] * x[j]
        x[i] = acc / LU[i, i]


@kernel
def palm_motion(H, grad, centre, max_rotation, out):
    """Solve ``H x = grad`` (6, 6), (6,) for the twist ``x = [r, u]`` about ``centre`` (3,) and
    write its motion ``T_delta`` (4, 4) into ``out``; a rotation beyond ``max_rotation``
    (radians) is scaled down with its translation. A ridge of ``1e-12 trace(H)`` keeps the
    directions the surfaces leave free (a pad sliding on a plane) at zero motion."""
    ridged, rhs, x = np.empty((6, 6)), np.empty(6), np.empty(6)
    trace = 0.0
    for i in range(6):
        trace += H[i, i]
    for i in range(6):
        for j in range(6):
            ridged[i, j] = H[i, j]
        ridged[i, i] += 1e-12 * max(trace, 1e-300)
        rhs[i] = grad[i]
    solve_small(ridged, rhs, x)
    theta2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2]
    scale = min(1.0, max_rotation / max(np.sqrt(theta2), 1e-300))
    for i in range(6):
        x[i] *= scale
    theta2 *= scale * scale
    theta = np.sqrt(theta2)
    if theta < 1e-9:  # Rodrigues: R = I + c1 [r]x + c2 [r]x^2
        c1, c2 = 1.0, 0.5
    else:
        c1, c2 = np.sin(theta) / theta, (1.0 - np.cos(theta)) / theta2
    r0, r1, r2 = x[0], x[1], x[2]
    K = ((0.0, -r2, r1), (r2, 0.0, -r0), (-r1, r0, 0.0))
    for i in range(3):
        for j in range(3):
            KK = K[i][0] * K[0][j] + K[i][1] * K[1][j] + K[i][2] * K[2][j]
            out[i, j] = (1.0 if i == j else 0.0) + c1 * K[i][j] + c2 * KK
    for i in range(3):
        out[i, 3] = centre[i] + x[3 + i] - (out[i, 0] * centre[0] + out[i, 1] * centre[1]
                                            + out[i, 2] * centre[2])
        out[3, i] = 0.0
    out[3, 3] = 1.0


@kernel
def palm_motions(H, grad, centre, max_rotation):
    """:func:`palm_motion` of B systems ``H`` (B, 6, 6), ``grad`` (B, 6) about ``centre`` (B, 3):
    the motions (B, 4, 4)."""
    out = np.empty((H.shape[0], 4, 4))
    for b in range(H.shape[0]):
        palm_motion(H[b], grad[b], centre[b], max_rotation, out[b])
    return out


@kernel
def palm_updates(T, rotations, positions, origin, fit_count, M, N, v, w, s, count, alpha2,
                 max_rotation):
    """One palm step of every fit: ``T_delta @ T`` with ``T_delta`` from :func:`palm_motion`
    of the fit's palm normal equations, (B, 4, 4)."""
    n_fits = rotations.shape[0]
    out = np.empty((n_fits, 4, 4))
    H, grad, centre, delta = np.empty((6, 6)), np.empty(6), np.empty(3), np.empty((4, 4))
    sums = _PalmMoments(origin, fit_count, M, N, v, w, s, count)
    for b in range(n_fits):
        _palm_system(b, T, rotations, positions, sums, alpha2, H, grad, centre)
        for j in range(3):
            centre[j] += origin[b, j]
        palm_motion(H, grad, centre, max_rotation, delta)
        for i in range(4):
            for j in range(4):
                out[b, i, j] = (delta[i, 0] * T[b, 0, j] + delta[i, 1] * T[b, 1, j]
                                + delta[i, 2] * T[b, 2, j] + delta[i, 3] * T[b, 3, j])
    return out


@kernel
def finger_systems(T, rotations, positions, J_linear, J_angular, origin, M, N, v, w, count, alpha):
    """Normal equations of every fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b`` (B, n).

    Args:
        T: palm poses, (B, 4, 4).
        rotations, positions, J_linear, J_angular: contact-link kinematics, gripper frame,
            (B, L, 3, 3), (B, L, 3), (B, L, 3, n), (B, L, 3, n).
        origin, M, N, v, w, count: from :func:`group_moments`.
        alpha: the normal weight, metres.
    """
    n_fits, n_links, n = rotations.shape[0], rotations.shape[1], J_linear.shape[3]
    AtA, Atb = np.zeros((n_fits, n, n)), np.zeros((n_fits, n))
    A, a, P, r, rn = np.empty((3, 3)), np.empty(3), np.empty(12), np.empty(12), np.empty(9)
    F, FM = np.zeros((n, 12)), np.empty((n, 12))
    used = np.empty(n, np.bool_)
    Jv, Jw = np.empty((3, n)), np.empty((3, n))
    for b in range(n_fits):
        for l in range(n_links):
            g = b * n_links + l
            if count[g] == 0.0:
                continue
            _group_pose(T[b], rotations[b, l], positions[b, l], origin[b], A, a)
            _vec_pose(A, a, P)
            _residual(M[g], v[g], P, r)
            for i in range(3):  # the link Jacobians in the object frame
                for m in range(n):
                    Jv[i, m] = T[b, i, 0] * J_linear[b, l, 0, m] + T[b, i, 1] * J_linear[b, l, 1, m] \
                        + T[b, i, 2] * J_linear[b, l, 2, m]
                    Jw[i, m] = T[b, i, 0] * J_angular[b, l, 0, m] + T[b, i, 1] * J_angular[b, l, 1, m] \
                        + T[b, i, 2] * J_angular[b, l, 2, m]
            for m in range(n):  # F[m, 3j:3j+3] = Jw_m x A[:, j], F[m, 9:] = Jv_m
                for j in range(3):
                    F[m, 3 * j] = Jw[1, m] * A[2, j] - Jw[2, m] * A[1, j]
                    F[m, 3 * j + 1] = Jw[2, m] * A[0, j] - Jw[0, m] * A[2, j]
                    F[m, 3 * j + 2] = Jw[0, m] * A[1, j] - Jw[1, m] * A[0, j]
                    F[m, 9 + j] = Jv[j, m]
            _add_sandwich(F, M[g], n, 12, 1.0, AtA[b], FM, used)
            for m in range(n):
                if not used[m]:  # a joint that does not move the link: a zero row adds +0
                    continue
                acc = 0.0
                for j in range(12):
                    acc += F[m, j] * r[j]
                Atb[b, m] += acc
            if alpha > 0.0:
                _add_sandwich(F, N[g], n, 9, alpha * alpha, AtA[b], FM, used)
                _normal_residual(N[g], P, w[g], rn)
                for m in range(n):
                    if not used[m]:
                        continue
                    acc = 0.0
                    for j in range(9):
                        acc += F[m, j] * rn[j]
                    Atb[b, m] -= alpha * alpha * acc
    return AtA, Atb


@kernel
def points_in_object(T, rotations, positions, fit, link, points_link, normals_link):
    """Gripper points and normals moved into the object frame: point ``i`` (on contact link
    ``link[i]`` of fit ``fit[i]``) at ``A_g x_i + a_g``, its normal ``A_g nu_i``.

    Args:
        T: palm poses, (B, 4, 4).
        rotations, positions: contact-link poses, gripper frame, (B, L, 3, 3), (B, L, 3).
        fit, link: (K,) integers.
        points_link, normals_link: link-frame points (metres) and normals, (K, 3).

    Returns:
        points (K, 3), metres, and normals (K, 3), object frame.
    """
    points, normals = np.empty((len(fit), 3)), np.empty((len(fit), 3))
    A, a, no_origin = np.empty((1, 3, 3)), np.empty((1, 3)), np.zeros(3)
    last = (-1, -1)
    for k in range(len(fit)):
        if (fit[k], link[k]) != last:
            last = (fit[k], link[k])
            _group_pose(T[fit[k]], rotations[fit[k], link[k]], positions[fit[k], link[k]], no_origin, A[0], a[0])
        place(A, a, 0, points_link, normals_link, k, points, normals, k)
    return points, normals


@kernel(inline=True)
def place(A, a, l, x, nu, k, points, normals, i):
    """``points[i] = A[l] x[k] + a[l]`` and ``normals[i] = A[l] nu[k]``, in place: link-frame point
    and normal ``k`` moved by the pose ``A[l]`` (3, 3), ``a[l]`` (3,) of its link in the object
    frame (``_group_pose``)."""
    for j in range(3):
        points[i, j] = A[l, j, 0] * x[k, 0] + A[l, j, 1] * x[k, 1] + A[l, j, 2] * x[k, 2] + a[l, j]
        normals[i, j] = A[l, j, 0] * nu[k, 0] + A[l, j, 1] * nu[k, 1] + A[l, j, 2] * nu[k, 2]
