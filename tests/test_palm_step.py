"""The palm step solves the paper's augmented least squares (eq. 5, 8, 10)."""

import numpy as np
import pytest
from _builders import random_rotation

from isf.fitting._palm_step import palm_step
from isf.se3 import exp_so3, rotation_angle, skew


def _unit(v):
    return v / np.linalg.norm(v, axis=1)[:, None]


def paper_least_squares(p, n_p, q, n_q, alpha):
    """x = (A^T A)^-1 A^T b with rows (5a)-(5b) and the normal rows of (8), stacked as in (10)."""
    A = np.vstack([np.c_[np.cross(p, n_q), n_q],
                   np.c_[alpha * np.cross(n_p, n_q), np.zeros_like(n_q)]])
    b = np.r_[np.einsum("ij,ij->i", q - p, n_q), -alpha * np.einsum("ij,ij->i", n_p, n_q) - alpha]
    return np.linalg.lstsq(A, b, rcond=None)[0]


@pytest.mark.parametrize("seed", range(10))
def test_palm_step_solves_equation_10(seed):
    rng = np.random.default_rng(seed)
    p = rng.normal(scale=0.02, size=(80, 3)) + rng.normal(scale=0.05, size=3)
    n_p, n_q = _unit(rng.normal(size=(80, 3))), _unit(rng.normal(size=(80, 3)))
    q = p + rng.normal(scale=0.002, size=p.shape)
    x = paper_least_squares(p, n_p, q, n_q, alpha=0.01)
    T = palm_step(p, n_p, q, n_q, normal_weight=0.01, max_rotation=np.pi)
    # Same rotation vector; the translation is that of the same linear motion,
    # with exp(r) applied about the points' centroid c.
    r, t = x[:3], x[3:]
    c = p.mean(axis=0)
    np.testing.assert_allclose(T[:3, :3], exp_so3(r), atol=1e-9)
    t_about_c = t + skew(r) @ c  # (I + r^) p + t == c + (I + r^)(p - c) + t_about_c
    np.testing.assert_allclose(T[:3, 3], c + t_about_c - exp_so3(r) @ c, atol=1e-9)


def test_repeated_palm_steps_recover_a_rigid_motion():
    rng = np.random.default_rng(1)
    q = rng.normal(scale=0.03, size=(200, 3))
    n_q = _unit(rng.normal(size=(200, 3)))
    R_true, t_true = random_rotation(rng, 0.2), np.array([0.004, -0.003, 0.002])
    # contact points = object points moved away by the inverse motion; normals reversed.
    p = (q - t_true) @ R_true
    n_p = -(n_q @ R_true)
    T = np.eye(4)
    for _ in range(30):
        moved = p @ T[:3, :3].T + T[:3, 3]
        T = palm_step(moved, n_p @ T[:3, :3].T, q, n_q, normal_weight=0.01, max_rotation=0.3) @ T
    assert rotation_angle(T[:3, :3].T @ R_true) < 1e-9
    np.testing.assert_allclose(T[:3, 3], t_true, atol=1e-10)


def test_rotation_step_is_limited():
    rng = np.random.default_rng(2)
    q = rng.normal(scale=0.03, size=(100, 3))
    n_q = _unit(rng.normal(size=(100, 3)))
    R_big = random_rotation(rng, 1.0)
    p = q @ R_big
    T = palm_step(p, -(n_q @ R_big), q, n_q, normal_weight=0.01, max_rotation=0.3)
    assert rotation_angle(T[:3, :3]) == pytest.approx(0.3, abs=1e-9)


def test_compiled_palm_motion_equals_the_reference_palm_step():
    """The engine's compiled solve of the palm step (partial-pivoting elimination, Rodrigues)
    gives the motion of the reference's numpy solve."""
    from isf.fitting import reference

    rng = np.random.default_rng(3)
    p = rng.normal(scale=0.02, size=(50, 3))
    n_p, n_q = _unit(rng.normal(size=(50, 3))), _unit(rng.normal(size=(50, 3)))
    q = p + rng.normal(scale=0.003, size=p.shape)
    for max_rotation in (np.pi, 0.01):
        np.testing.assert_allclose(
            palm_step(p, n_p, q, n_q, normal_weight=0.01, max_rotation=max_rotation),
            reference.palm_step(p, n_p, q, n_q, 0.01, max_rotation), rtol=0, atol=1e-12)
