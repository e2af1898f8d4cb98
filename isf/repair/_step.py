"""The arithmetic of a collision-repair step, compiled (:mod:`isf.repair.clearance`).

* :func:`to_object`: gripper points given in their links' frames, in the object frame;
* :func:`motion_rows`: the rows ``n^T A`` that map a step ``x = (v, w, dq)`` to the motion of
  points along directions ``n``;
* :func:`step_qp`: the step's QP (contact least squares, regularisation, one slack per
  geometry element, clearance rows, trust region and joint limits).

Units: SI in and out, except the QP, which is in millimetres (the repair scales its
variables, see ``isf.repair.clearance.ClearanceRepair``). The functions release the GIL, so worker
threads repairing side by side overlap.
"""

from __future__ import annotations

import numpy as np

from ..compiled.kernels import kernel
from ..fitting.moment_kernels import link_poses

__all__ = ["motion_rows", "step_qp", "to_object"]


@kernel
def to_object(T, R, p, owner, local):
    """Object-frame positions (M, 3) of points ``local`` (M, 3) given in the frames of links
    ``owner`` (M,), whose rotations ``R`` (L, 3, 3) and origins ``p`` (L, 3) are in the gripper
    frame, for the palm pose ``T`` (4, 4)."""
    rotation, origin = np.empty((len(R), 3, 3)), np.empty((len(R), 3))
    link_poses(T, R, p, rotation, origin)
    out = np.empty((len(owner), 3))
    for m in range(len(owner)):
        A, a = rotation[owner[m]], origin[owner[m]]
        for i in range(3):
            out[m, i] = A[i, 0] * local[m, 0] + A[i, 1] * local[m, 1] + A[i, 2] * local[m, 2] + a[i]
    return out


@kernel
def motion_rows(T, R, p, J, owner, local, centre, normals):
    """Rows ``n^T A`` (M, 6 + n) of points ``local`` (M, 3) of links ``owner`` (M,) along
    object-frame directions ``normals`` (M, 3).

    ``A`` maps a step ``x = (v, w, dq)`` (palm translation, palm rotation about ``centre``
    (3,), object frame, and joint step) to the point's motion ``v + w x (c - centre) + T_R J dq``
    (``c`` the point in the object frame, ``J`` its point Jacobian). Link poses ``R`` (L, 3, 3),
    ``p`` (L, 3) and frame Jacobians ``J`` (L, 6, n) (linear rows first) are in the gripper
    frame; ``T`` (4, 4) is the palm pose.
    """
    n_joints = J.shape[2]
    rows = np.empty((len(owner), 6 + n_joints))
    r, n_g = np.empty(3), np.empty(3)
    for m in range(len(owner)):
        link = owner[m]
        for i in range(3):  # the point from its link's origin, and the direction, gripper frame
            r[i] = (R[link, i, 0] * local[m, 0] + R[link, i, 1] * local[m, 1]
                    + R[link, i, 2] * local[m, 2])
            n_g[i] = T[0, i] * normals[m, 0] + T[1, i] * normals[m, 1] + T[2, i] * normals[m, 2]
        c = np.empty(3)  # the point, object frame, from the centre
        for i in range(3):
            c[i] = (T[i, 0] * (r[0] + p[link, 0]) + T[i, 1] * (r[1] + p[link, 1])
                    + T[i, 2] * (r[2] + p[link, 2]) + T[i, 3] - centre[i])
        nx, ny, nz = normals[m, 0], normals[m, 1], normals[m, 2]
        rows[m, 0], rows[m, 1], rows[m, 2] = nx, ny, nz
        rows[m, 3] = c[1] * nz - c[2] * ny
        rows[m, 4] = c[2] * nx - c[0] * nz
        rows[m, 5] = c[0] * ny - c[1] * nx
        rx = r[1] * n_g[2] - r[2] * n_g[1]  # r x n_g: the rotation part of the joints' motion
        ry = r[2] * n_g[0] - r[0] * n_g[2]
        rz = r[0] * n_g[1] - r[1] * n_g[0]
        for k in range(n_joints):
            rows[m, 6 + k] = (n_g[0] * J[link, 0, k] + n_g[1] * J[link, 1, k]
                              + n_g[2] * J[link, 2, k] + rx * J[link, 3, k]
                              + ry * J[link, 4, k] + rz * J[link, 5, k])
    return rows


@kernel
def step_qp(contact_rows, residual, clearance_rows, violation, element, unit, regularisation,
            contact_weight, slack_weight, palm_step, joint_lower, joint_upper):
    """The step's QP ``min 1/2 z^T H z + f^T z, lo <= A z <= hi`` over ``z = (x_mm, s)``.

    Args:
        contact_rows: rows of the contact points (K, nx), metres per SI unit of ``x``.
        residual: their signed distances from their tangent planes, (K,), millimetres.
        clearance_rows: rows of the clearance points (M, nx), like ``contact_rows``.
        violation: their violations ``floor - height`` (M,), millimetres.
        element: their geometry elements (M,), integers >= 0.
        unit: millimetres of motion per unit of ``x_mm``, per variable (nx,).
        regularisation: the step's weight matrix (nx, nx).
        contact_weight, slack_weight: weights of the squared contact residuals and slacks.
        palm_step: trust region of the palm variables of ``x_mm`` (6,).
        joint_lower, joint_upper: bounds of the joint variables of ``x_mm`` (n,).

    Returns:
        ``(H, f, A, lo, hi)``: ``x_mm`` first, then one slack per element that has rows (in
        increasing element order); the rows are the clearance rows (``n^T A x + s_e >=
        violation``), the slacks (``s_e >= 0``), then the palm and joint bounds.
    """
    nx = len(unit)
    m = len(violation)
    slot = np.full(element.max() + 1 if m else 0, -1, np.int64)  # each element's slack
    for i in range(m):
        slot[element[i]] = 0
    ns = 0
    for e in range(len(slot)):
        if slot[e] == 0:
            slot[e] = ns
            ns += 1
    H = np.zeros((nx + ns, nx + ns))
    f = np.zeros(nx + ns)
    for a in range(nx):
        for b in range(nx):
            acc = 0.0
            for k in range(len(residual)):
                acc += contact_rows[k, a] * contact_rows[k, b]
            H[a, b] = 2.0 * contact_weight * acc * unit[a] * unit[b] + regularisation[a, b]
        acc = 0.0
        for k in range(len(residual)):
            acc += contact_rows[k, a] * residual[k]
        f[a] = 2.0 * contact_weight * acc * unit[a]
    for e in range(ns):
        H[nx + e, nx + e] = 2.0 * slack_weight
    A = np.zeros((m + ns + nx, nx + ns))
    lo, hi = np.empty(m + ns + nx), np.empty(m + ns + nx)
    for i in range(m):
        for a in range(nx):
            A[i, a] = clearance_rows[i, a] * unit[a]
        A[i, nx + slot[element[i]]] = 1.0
        lo[i], hi[i] = violation[i], np.inf
    for e in range(ns):
        A[m + e, nx + e] = 1.0
        lo[m + e], hi[m + e] = 0.0, np.inf
    for a in range(nx):
        A[m + ns + a, a] = 1.0
        if a < 6:
            lo[m + ns + a], hi[m + ns + a] = -palm_step[a], palm_step[a]
        else:
            lo[m + ns + a], hi[m + ns + a] = joint_lower[a - 6], joint_upper[a - 6]
    return H, f, A, lo, hi
