"""The moment form of IPFO: every inner step in O(1) per link, whatever the number of pairs.

With the correspondences fixed, the points of one link move rigidly: in the object frame
pair ``i`` of link group ``g`` (one link of one fit) sits at ``p_i = A_g x_i + a_g``
(``x_i`` its link-frame point, ``A_g = R_palm R_link``, ``a_g`` the link origin), so with
``y_i = vec([x_i; 1] (n^q_i)^T)`` (12) its point-to-plane residual is linear in ``y_i``:
``d_i = P_g . y_i - beta_i`` (``P_g = vec([A_g | a_g]^T)``, ``beta_i = (n^q_i)^T q_i``).
The same holds for the palm-step rows ``[(p_i - c) x n^q_i, n^q_i]``, the finger-step
rows ``(n^q_i)^T J_i`` and the normal terms (in ``u_i = vec(n^p_i (n^q_i)^T)``, 9).
Hence every sum IPFO needs (E, the palm normal equations, the finger normal equations)
is a small matrix expression in the per-group moments

``M_g = sum y y^T`` (12x12), ``v_g = sum beta y``, ``sum beta^2``, ``N_g = sum u u^T`` (9x9),
``w_g = sum u``, ``s_g = sum [x; 1]``,

built once per IPFO run from the pairs. The results equal the pair-by-pair sums of
:class:`isf.ipfo.PairBatch` to round-off (tested).
"""

from __future__ import annotations

import numpy as np

from .gripper import LinkKinematics
from .segments import Segments

__all__ = ["PairMoments"]


def _skew_columns(U: np.ndarray) -> np.ndarray:
    """``S[..., r, j, k] = ([U[..., :, j]]_x)[r, k]`` for U (..., 3, J): (..., 3, J, 3)."""
    x, y, z = U[..., 0, :], U[..., 1, :], U[..., 2, :]
    zero = np.zeros_like(x)
    rows = [np.stack([zero, -z, y], axis=-1), np.stack([z, zero, -x], axis=-1), np.stack([-y, x, zero], axis=-1)]
    return np.stack(rows, axis=-3)


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
    """

    def __init__(self, fit, link, points_link, normals_link, targets, target_normals, n_fits: int):
        n_links = int(link.max()) + 1
        order = np.lexsort((link, fit))
        fit, link = fit[order], link[order]
        group_id = fit * n_links + link
        first = np.r_[True, group_id[1:] != group_id[:-1]]
        self.groups = Segments(np.cumsum(first) - 1)
        self.group_fit = fit[first]
        self.group_link = link[first]
        self.fits = Segments(self.group_fit)
        if len(self.fits) != n_fits:
            raise ValueError("every fit needs at least one pair")
        # Object coordinates relative to each fit's target centroid keep the sums well conditioned.
        targets = targets[order]
        self.origin = Segments(fit).mean(targets)
        n = target_normals[order]
        beta = np.einsum("kj,kj->k", targets - self.origin[fit], n)
        z = np.concatenate([points_link[order], np.ones((len(fit), 1))], axis=1)
        y = (z[:, :, None] * n[:, None, :]).reshape(-1, 12)
        u = (normals_link[order][:, :, None] * n[:, None, :]).reshape(-1, 9)
        sums = self.groups.sum
        slices = self.groups.slices()
        self.M = np.stack([y[s].T @ y[s] for s in slices])
        self.N = np.stack([u[s].T @ u[s] for s in slices])
        self.v = sums(y * beta[:, None])
        self.beta2 = sums(beta * beta)
        self.w = sums(u)
        self.s = sums(z)
        self.count = self.groups.counts.astype(float)

    def _poses(self, T: np.ndarray, links: LinkKinematics):
        """Per group: ``A`` (G, 3, 3), ``a`` (G, 3) (centred object frame) and the palm rotation (G, 3, 3)."""
        f, k = self.group_fit, self.group_link
        R_palm = T[f, :3, :3]
        A = R_palm @ links.rotations[f, k]
        a = np.einsum("gij,gj->gi", R_palm, links.positions[f, k]) + T[f, :3, 3] - self.origin[f]
        return A, a, R_palm

    @staticmethod
    def _vec_P(A: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``vec([A | a]^T)``, (G, 12)."""
        return np.concatenate([A.transpose(0, 2, 1), a[:, None, :]], axis=1).reshape(-1, 12)

    def errors(self, T: np.ndarray, links: LinkKinematics, normal_weight: float) -> np.ndarray:
        """``E = E_p + alpha^2 E_n`` of each fit, (B,), m^2."""
        A, a, _ = self._poses(T, links)
        p = self._vec_P(A, a)
        a9 = A.transpose(0, 2, 1).reshape(-1, 9)
        Ep = np.einsum("gi,gij,gj->g", p, self.M, p) - 2.0 * np.einsum("gi,gi->g", p, self.v) + self.beta2
        En = np.einsum("gi,gij,gj->g", a9, self.N, a9) + 2.0 * np.einsum("gi,gi->g", a9, self.w) + self.count
        return self.fits.sum(Ep + normal_weight**2 * En)

    def palm_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's palm step about its contact centroid.

        Returns:
            ``H`` (B, 6, 6), ``g`` (B, 6) for the twist ``[r, u]`` and the centroids (B, 3), object frame.
        """
        A, a, _ = self._poses(T, links)
        count = self.fits.sum(self.count)
        centre = self.fits.sum(np.einsum("gij,gj->gi", A, self.s[:, :3]) + a * self.s[:, 3:]) / count[:, None]
        P = np.concatenate([A, (a - centre[self.group_fit])[:, :, None]], axis=2)  # [A | a - c], (G, 3, 4)
        G = np.zeros((len(A), 6, 4, 3))
        G[:, :3] = _skew_columns(P)
        G[:, 3:, 3, :] = np.eye(3)
        G = G.reshape(-1, 6, 12)
        residual = self.v - np.einsum("gij,gj->gi", self.M, self._vec_P(A, a))
        H = self.fits.sum(G @ self.M @ G.transpose(0, 2, 1))
        g = self.fits.sum(np.einsum("gij,gj->gi", G, residual))
        if normal_weight > 0.0:
            Gn = _skew_columns(A).reshape(-1, 3, 9)
            a9 = A.transpose(0, 2, 1).reshape(-1, 9)
            H[:, :3, :3] += normal_weight**2 * self.fits.sum(Gn @ self.N @ Gn.transpose(0, 2, 1))
            g[:, :3] -= normal_weight**2 * self.fits.sum(
                np.einsum("gij,gj->gi", Gn, np.einsum("gij,gj->gi", self.N, a9) + self.w))
        return H, g, centre + self.origin

    def finger_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b`` (B, n)."""
        A, a, R_palm = self._poses(T, links)
        f, k = self.group_fit, self.group_link
        Jv = R_palm @ links.J_linear[f, k]  # (G, 3, n), object frame
        Jw = R_palm @ links.J_angular[f, k]
        n = Jv.shape[2]
        S = _skew_columns(A)  # (G, 3, 3, 3): S[g, r, j, k] = (A[:, j] x e_k)[r]
        F = np.zeros((len(A), n, 4, 3))
        F[:, :, :3, :] = np.einsum("grn,grjk->gnjk", Jw, S)
        F[:, :, 3, :] = Jv.transpose(0, 2, 1)
        F = F.reshape(-1, n, 12)
        residual = self.v - np.einsum("gij,gj->gi", self.M, self._vec_P(A, a))
        AtA = self.fits.sum(F @ self.M @ F.transpose(0, 2, 1))
        Atb = self.fits.sum(np.einsum("gij,gj->gi", F, residual))
        if normal_weight > 0.0 and np.any(links.J_angular):
            Fn = normal_weight * np.einsum("grn,grjk->gnjk", Jw, S).reshape(-1, n, 9)
            a9 = A.transpose(0, 2, 1).reshape(-1, 9)
            AtA += self.fits.sum(Fn @ self.N @ Fn.transpose(0, 2, 1))
            Atb -= normal_weight * self.fits.sum(
                np.einsum("gij,gj->gi", Fn, np.einsum("gij,gj->gi", self.N, a9) + self.w))
        return AtA, Atb
