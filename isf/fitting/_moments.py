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
:class:`isf.fitting.reference.PairBatch` to round-off (tested).

Groups are dense: every fit has one group per contact link (a link without pairs has zero
moments), so the groups of a pose are a reshape of the (B, L) link kinematics, not a gather.
The sums are compiled (:mod:`isf.fitting.moment_kernels`).
"""

from __future__ import annotations

import numpy as np

from ..gripper.model import LinkKinematics
from . import moment_kernels as kernels

__all__ = ["PairMoments"]


class PairMoments:
    """Per-link-group moments of B fits' matched pairs (see the module docstring).

    Args:
        fit: fit of each pair, (K,), every fit ``0 .. n_fits - 1`` present.
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
        fit, link = np.asarray(fit, dtype=np.int64), np.asarray(link, dtype=np.int64)
        n_links = int(link.max()) + 1 if n_links is None else n_links
        if len(fit) == 0 or np.bincount(fit, minlength=n_fits).min() == 0:
            raise ValueError("every fit needs at least one pair")
        self.shape = (n_fits, n_links)
        (self.origin, self.fit_count, self.M, self.N, self.v, self.beta2, self.w, self.s,
         self.count) = kernels.group_moments(fit, link, *(np.asarray(a, dtype=float) for a in (
             points_link, normals_link, targets, target_normals)), n_fits, n_links)

    def errors(self, T: np.ndarray, links: LinkKinematics, normal_weight: float) -> np.ndarray:
        """``E = E_p + alpha^2 E_n`` of each fit, (B,), m^2.

        Args:
            T: palm poses ``T_object_gripper``, (B, 4, 4).
            links: contact-link kinematics (arrays (B, L, ...)).
            normal_weight: ``alpha``, metres.
        """
        return kernels.fit_errors(T, links.rotations, links.positions, self.origin, self.M, self.N,
                                  self.v, self.beta2, self.w, self.count, normal_weight**2)

    def palm_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's palm step about its contact centroid.

        Returns:
            ``H`` (B, 6, 6), ``g`` (B, 6) for the twist ``[r, u]`` and the centroids (B, 3),
            object frame.
        """
        return kernels.palm_systems(T, links.rotations, links.positions, self.origin,
                                    self.fit_count, self.M, self.N, self.v, self.w, self.s,
                                    self.count, normal_weight**2)

    def palm_update(self, T: np.ndarray, links: LinkKinematics, normal_weight: float,
                    max_rotation: float) -> np.ndarray:
        """Each fit's palm step applied: the poses after it, (B, 4, 4) (see
        :func:`isf.fitting._palm_step.palm_motions` for the step)."""
        return kernels.palm_updates(T, links.rotations, links.positions, self.origin,
                                    self.fit_count, self.M, self.N, self.v, self.w, self.s,
                                    self.count, normal_weight**2, max_rotation)

    def finger_system(self, T: np.ndarray, links: LinkKinematics, normal_weight: float):
        """Normal equations of each fit's finger least squares: ``A^T A`` (B, n, n), ``A^T b``
        (B, n)."""
        return kernels.finger_systems(T, links.rotations, links.positions, links.J_linear,
                                      links.J_angular, self.origin, self.M, self.N, self.v, self.w,
                                      self.count, normal_weight)
