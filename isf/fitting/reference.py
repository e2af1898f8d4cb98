"""Plain-Python reference of ISF (paper Algorithms 1 and 2): the test oracle of the compiled engine.

:class:`PairBatch` evaluates the matched pairs of many fits pair by pair, in numpy.
"""

from __future__ import annotations

import numpy as np

from ..gripper.model import Gripper, LinkKinematics
from ..se3 import cross
from .segments import Segments

__all__ = ["PairBatch"]


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

    def to_object(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gripper-frame points and normals (K, 3) moved by each pair's palm pose ``T`` (B, 4, 4)."""
        Tk = T[self.segments.ids]
        R = Tk[:, :3, :3]
        return _rotate(R, points) + Tk[:, :3, 3], _rotate(R, normals)

    def residuals(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point-to-plane distances (K,) in metres and normal terms ``(R n^p)^T n^q + 1`` (K,).

        Args:
            T: palm poses ``T_object_gripper`` of the B fits, (B, 4, 4).
            points, normals: gripper-frame contact points and normals, (K, 3).
        """
        p, n = self.to_object(T, points, normals)
        d = np.einsum("kj,kj->k", p - self.targets, self.target_normals)
        c = np.einsum("kj,kj->k", n, self.target_normals) + 1.0
        return d, c

    def errors(self, T: np.ndarray, points: np.ndarray, normals: np.ndarray, normal_weight: float) -> np.ndarray:
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
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b`` (B, n)."""
        A, b, An, bn = self.finger_rows(T, points, normals, offsets, links, normal_weight)
        AtA = self.segments.sum(A[:, :, None] * A[:, None, :])
        Atb = self.segments.sum(A * b[:, None])
        if An is not None:
            AtA += self.segments.sum(An[:, :, None] * An[:, None, :])
            Atb += self.segments.sum(An * bn[:, None])
        return AtA, Atb
