"""The moment form of IPFO: every inner step in O(1) per link, whatever the number of pairs.

With the correspondences fixed, the points of one link move rigidly: in the object frame
pair ``i`` of link group ``g`` (one link of one fit) sits at ``p_i = A_g x_i + a_g``
(``x_i`` its link-frame point, ``A_g = R_palm R_link``, ``a_g`` the link origin), so with
``y_i = vec([x_i; 1] (n^q_i)^T)`` (12) its point-to-plane residual is linear in ``y_i``:
``d_i = P_g . y_i - beta_i`` (``P_g = vec([A_g | a_g]^T)``, ``beta_i = (n^q_i)^T q_i``).
The same holds for the palm-step rows ``[(p_i - c) x n^q_i, n^q_i]``, the finger-step
rows ``(n^q_i)^T J_i`` and the normal terms (in ``u_i = vec(nu_i (n^q_i)^T)``, 9, with
``nu_i`` the link-frame normal: ``(n^p_i)^T n^q_i = P_g[:9] . u_i``).
Hence every sum IPFO needs (E, the palm normal equations, the finger normal equations)
is a small matrix expression in the per-group moments

``M_g = sum y y^T`` (12x12), ``v_g = sum beta y``, ``sum beta^2``, ``N_g = sum u u^T`` (9x9),
``w_g = sum u``, ``s_g = sum [x; 1]``,

built once per IPFO run from the pairs. The results equal the pair-by-pair sums of
:class:`isf.ipfo.PairBatch` to round-off (tested).

Groups are dense: every fit has one group per contact link (a link without pairs has zero
moments), so the groups of a pose are a reshape of the (B, L) link kinematics, not a gather.
"""

from __future__ import annotations

import numpy as np

from .gripper import LinkKinematics
from .segments import Segments, run_starts

__all__ = ["PairMoments"]


def _levi_civita() -> np.ndarray:
    """``eps[i, m, k]``, (3, 3, 3): ``[u]_x[i, k] = sum_m eps[i, m, k] u[m]``."""
    eps = np.zeros((3, 3, 3))
    for i, m, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps[i, m, k], eps[i, k, m] = 1.0, -1.0
    return eps


_EPS = _levi_civita()
_EYE3 = np.eye(3)
# Skew columns as one matmul with a constant 0/+-1 matrix, exact (one nonzero term per
# entry): for U (3, J) flattened row-major, (vec(U) @ _SKEW[J]).reshape(3, J, 3)
# is S with S[r, j, k] = ([U[:, j]]_x)[r, k].
_SKEW = {J: np.einsum("rmk,jJ->mjrJk", _EPS, np.eye(J)).reshape(3 * J, 9 * J) for J in (3, 4)}


def _skew_columns(U: np.ndarray) -> np.ndarray:
    """``S[g, r, j, k] = ([U[g, :, j]]_x)[r, k]`` for U (G, 3, J), J in (3, 4): (G, 3, J, 3)."""
    J = U.shape[-1]
    return (U.reshape(-1, 3 * J) @ _SKEW[J]).reshape(-1, 3, J, 3)


class PairMoments:
    """Per-link-group moments of B fits' matched pairs (see the module docstring).

    Args:
        fit: fit of each pair, (K,), non-decreasing.
        link: contact link of each pair, (K,).
        points_link: link-frame contact points ``x_i``, (K, 3), metres.
        normals_link: link-frame contact normals ``nu_i``, (K, 3).
        targets: object points ``q_i``, (K, 3), metres (object frame).
        target_normals: object normals ``n^q_i``, (K, 3).
        n_fits: B.
        n_links: L, the gripper's number of contact links (default ``link.max() + 1``).
    """

    def __init__(self, fit, link, points_link, normals_link, targets, target_normals, n_fits: int,
                 n_links: int | None = None):
        n_links = int(link.max()) + 1 if n_links is None else n_links
        self.shape = (n_fits, n_links)
        self._fit_starts = np.arange(0, n_fits * n_links, n_links)
        group_id = fit * n_links + link
        if np.any(group_id[1:] < group_id[:-1]):  # pairs of one link of one fit must be adjacent
            order = np.argsort(group_id, kind="stable")
            fit, group_id = fit[order], group_id[order]
            points_link, normals_link = points_link[order], normals_link[order]
            targets, target_normals = targets[order], target_normals[order]
        first = run_starts(group_id)
        groups = Segments(np.cumsum(first) - 1)
        fits = Segments(fit)
        if len(fits) != n_fits:
            raise ValueError("every fit needs at least one pair")
        # Object coordinates relative to each fit's target centroid keep the sums well conditioned.
        self.origin = fits.mean(targets)
        n = target_normals
        beta = np.einsum("kj,kj->k", targets - self.origin[fit], n)
        z = np.concatenate([points_link, np.ones((len(fit), 1))], axis=1)
        y = (z[:, :, None] * n[:, None, :]).reshape(-1, 12)
        u = (normals_link[:, :, None] * n[:, None, :]).reshape(-1, 9)
        slices = groups.slices()
        present = group_id[first]

        def dense(values: np.ndarray) -> np.ndarray:
            """Values of the present groups (G', ...) in all B*L groups (zeros elsewhere)."""
            out = np.zeros((n_fits * n_links,) + values.shape[1:])
            out[present] = values
            return out

        self.M = dense(np.stack([y[s].T @ y[s] for s in slices]))
        self.N = dense(np.stack([u[s].T @ u[s] for s in slices]))
        self.v = dense(groups.sum(y * beta[:, None]))
        self.beta2 = dense(groups.sum(beta * beta))
        self.w = dense(groups.sum(u))
        self.s = dense(groups.sum(z))
        self.count = dense(groups.counts.astype(float))
        self.fit_count = fits.counts.astype(float)

    def _fit_sum(self, values: np.ndarray) -> np.ndarray:
        """Per-fit sums of per-group ``values`` (G, ...) -> (B, ...).

        ``np.add.reduceat``, not ``sum(axis=1)`` (which adds three or more links in another
        order): with the absent links' exact zeros it adds the same numbers in the same order
        as a sum over the present groups only, so the dense layout changes no result bit.
        """
        return np.add.reduceat(values, self._fit_starts, axis=0)

    def _poses(self, T: np.ndarray, links: LinkKinematics):
        """Per group: ``A`` (G, 3, 3), ``a`` (G, 3) (centred object frame); and the palm
        rotations (B, 1, 3, 3)."""
        R_palm = T[:, None, :3, :3]
        A = (R_palm @ links.rotations).reshape(-1, 3, 3)
        a = np.einsum("bij,blj->bli", T[:, :3, :3], links.positions) + T[:, None, :3, 3]
        return A, (a - self.origin[:, None]).reshape(-1, 3), R_palm

    @staticmethod
    def _vec_P(A: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``vec([A | a]^T)``, (G, 12)."""
        return np.concatenate([A.transpose(0, 2, 1), a[:, None, :]], axis=1).reshape(-1, 12)

    def errors(self, T: np.ndarray, links: LinkKinematics, normal_weight: float) -> np.ndarray:
        """``E = E_p + alpha^2 E_n`` of each fit, (B,), m^2.

        Args:
            T: palm poses ``T_object_gripper``, (B, 4, 4).
            links: contact-link kinematics (arrays (B, L, ...)).
            normal_weight: ``alpha``, metres.
        """
        A, a, _ = self._poses(T, links)
        p = self._vec_P(A, a)
        a9 = p[:, :9]
        Ep = np.einsum("gi,gij,gj->g", p, self.M, p) - 2.0 * np.einsum("gi,gi->g", p, self.v) + self.beta2
        En = np.einsum("gi,gij,gj->g", a9, self.N, a9) + 2.0 * np.einsum("gi,gi->g", a9, self.w) + self.count
        return self._fit_sum(Ep + normal_weight**2 * En)

    def palm_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's palm step about its contact centroid.

        Returns:
            ``H`` (B, 6, 6), ``g`` (B, 6) for the twist ``[r, u]`` and the centroids (B, 3), object frame.
        """
        A, a, _ = self._poses(T, links)
        moment = np.einsum("gij,gj->gi", A, self.s[:, :3]) + a * self.s[:, 3:]
        centre = self._fit_sum(moment) / self.fit_count[:, None]
        offset = (a.reshape(self.shape + (3,)) - centre[:, None]).reshape(-1, 3, 1)
        P = np.concatenate([A, offset], axis=2)
        G = np.zeros((len(A), 6, 4, 3))
        G[:, :3] = _skew_columns(P)  # [A | a - c], (G, 3, 4)
        G[:, 3:, 3, :] = _EYE3
        G = G.reshape(-1, 6, 12)
        p = self._vec_P(A, a)
        residual = self.v - np.einsum("gij,gj->gi", self.M, p)
        H = self._fit_sum(G @ self.M @ G.transpose(0, 2, 1))
        g = self._fit_sum(np.einsum("gij,gj->gi", G, residual))
        if normal_weight > 0.0:
            Gn = G[:, :3, :9]  # the skew columns of A
            H[:, :3, :3] += normal_weight**2 * self._fit_sum(Gn @ self.N @ Gn.transpose(0, 2, 1))
            g[:, :3] -= normal_weight**2 * self._fit_sum(
                np.einsum("gij,gj->gi", Gn, np.einsum("gij,gj->gi", self.N, p[:, :9]) + self.w))
        return H, g, centre + self.origin

    def finger_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b`` (B, n)."""
        A, a, R_palm = self._poses(T, links)
        n = links.J_linear.shape[-1]
        Jv = (R_palm @ links.J_linear).reshape(-1, 3, n)  # (G, 3, n), object frame
        Jw = (R_palm @ links.J_angular).reshape(-1, 3, n)
        S = _skew_columns(A)  # (G, 3, 3, 3): S[g, r, j, k] = (A[:, j] x e_k)[r]
        F = np.zeros((len(A), n, 4, 3))
        F[:, :, :3, :] = np.einsum("grn,grjk->gnjk", Jw, S)
        F[:, :, 3, :] = Jv.transpose(0, 2, 1)
        F = F.reshape(-1, n, 12)
        p = self._vec_P(A, a)
        residual = self.v - np.einsum("gij,gj->gi", self.M, p)
        AtA = self._fit_sum(F @ self.M @ F.transpose(0, 2, 1))
        Atb = self._fit_sum(np.einsum("gij,gj->gi", F, residual))
        if normal_weight > 0.0 and np.any(links.J_angular):
            Fn = normal_weight * F[:, :, :9]
            AtA += self._fit_sum(Fn @ self.N @ Fn.transpose(0, 2, 1))
            Atb -= normal_weight * self._fit_sum(
                np.einsum("gij,gj->gi", Fn, np.einsum("gij,gj->gi", self.N, p[:, :9]) + self.w))
        return AtA, Atb
