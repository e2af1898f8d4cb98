"""The moment form of IPFO equals the pair-by-pair sums it replaces."""

import numpy as np
import pytest
from _builders import random_rotation

import isf
from isf.fitting._moments import PairMoments
from isf.fitting._palm_step import palm_motions, palm_steps
from isf.fitting.moment_kernels import solve_small
from isf.fitting.reference import PairBatch
from isf.fitting.segments import Segments
from isf.se3 import make_transform


@pytest.fixture(scope="module")
def case():
    """Random pairs of 5 fits of the three-finger hand (revolute, 3 links), far from the origin."""
    hand = isf.load_gripper("three-finger")
    rng = np.random.default_rng(11)
    counts = np.array([40, 7, 120, 33, 64])
    seg = Segments.from_counts(counts)
    index = np.concatenate([rng.choice(hand.n_points, c, replace=False) for c in counts])
    targets = rng.normal(scale=0.05, size=(len(index), 3)) + [0.4, -0.3, 0.8]
    normals = rng.normal(size=(len(index), 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    pairs = PairBatch(hand, seg, index, targets, normals)
    T = np.stack([make_transform(random_rotation(rng, 2.0), [0.4, -0.3, 0.8] + rng.normal(scale=0.05, size=3))
                  for _ in counts])
    q = rng.uniform(hand.lower, hand.upper, (len(counts), hand.n_joints))
    links = hand.link_kinematics_many(q)
    moments = PairMoments(seg.ids, hand.point_link[index], hand.points_link[index], hand.normals_link[index],
                          targets, normals, len(counts))
    return pairs, moments, T, links


def test_errors_equal_pairwise_sums(case):
    pairs, moments, T, links = case
    points, normals, _ = pairs.evaluate(links)
    expected = pairs.errors(T, points, normals, 0.01)
    np.testing.assert_allclose(moments.errors(T, links, 0.01), expected, rtol=1e-9, atol=1e-15)


def test_palm_system_gives_the_pairwise_palm_step(case):
    pairs, moments, T, links = case
    points, normals, _ = pairs.evaluate(links)
    expected = palm_steps(*pairs.to_object(T, points, normals), pairs.targets, pairs.target_normals,
                          pairs.segments, normal_weight=0.01, max_rotation=np.pi)
    H, g, centre = moments.palm_system(T, links, 0.01)
    np.testing.assert_allclose(palm_motions(H, g, centre, np.pi), expected, atol=1e-9)


def test_finger_system_equals_pairwise_normal_equations(case):
    pairs, moments, T, links = case
    points, normals, offsets = pairs.evaluate(links)
    AtA, Atb = pairs.finger_system(T, points, normals, offsets, links, 0.01)
    AtA_m, Atb_m = moments.finger_system(T, links, 0.01)
    np.testing.assert_allclose(AtA_m, AtA, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(Atb_m, Atb, rtol=1e-9, atol=1e-14)


def test_palm_update_applies_the_palm_step(case):
    pairs, moments, T, links = case
    H, g, centre = moments.palm_system(T, links, 0.01)
    expected = palm_motions(H, g, centre, 0.2) @ T
    np.testing.assert_allclose(moments.palm_update(T, links, 0.01, 0.2), expected, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 6, 16])
def test_small_solve_matches_lapack(n):
    rng = np.random.default_rng(n)
    H = rng.normal(size=(n, n))
    if n > 1:
        H[0, 0] = 0.0  # needs a row exchange
    rhs = rng.normal(size=n)
    x = np.empty(n)
    LU, y = H.copy(), rhs.copy()
    solve_small(LU, y, x)  # in place: overwrites LU and y
    np.testing.assert_allclose(x, np.linalg.solve(H, rhs), rtol=1e-10, atol=1e-12)


def _dense_sandwich(X, M, rows, cols, weight, out):
    """``out += weight * X M X^T`` summed term by term in column order, every term included
    (the plain triple loop the compiled sandwiches must equal bit for bit)."""
    XM = np.zeros((rows, cols))
    for i in range(rows):
        for j in range(cols):
            acc = 0.0
            for k in range(cols):
                acc += float(X[i, k]) * float(M[k, j])
            XM[i, j] = acc
    for i in range(rows):
        for j in range(rows):
            acc = 0.0
            for k in range(cols):
                acc += XM[i, k] * float(X[j, k])
            out[i, j] += weight * acc


@pytest.mark.parametrize("seed", range(3))
def test_structured_sandwiches_equal_the_full_sums_bit_for_bit(seed):
    from isf.fitting.moment_kernels import _add_palm_sandwich, _add_sandwich
    rng = np.random.default_rng(seed)
    Y = rng.normal(size=(30, 12))
    M = Y.T @ Y  # symmetric, like the pair moments
    # the palm's lever matrix: cross-product blocks of four columns, then [0 | I]
    G = np.zeros((6, 12))
    for j in range(4):
        c = rng.normal(size=3)
        G[0, 3 * j + 1], G[0, 3 * j + 2] = -c[2], c[1]
        G[1, 3 * j], G[1, 3 * j + 2] = c[2], -c[0]
        G[2, 3 * j], G[2, 3 * j + 1] = -c[1], c[0]
    G[3:, 9:] = np.eye(3)
    for cols, rows, weight in ((12, 6, 1.0), (9, 3, 0.37)):
        start = rng.normal(size=(6, 6))
        expected, got = start.copy(), start.copy()
        _dense_sandwich(G, M, rows, cols, weight, expected)
        _add_palm_sandwich(G, M, cols, weight, got, np.empty((6, 12)))
        np.testing.assert_array_equal(got, expected)
    # a finger's rows: the joints that do not move the link are zero rows
    F = rng.normal(size=(7, 12))
    F[[1, 4, 5]] = 0.0
    F[2, 9:] = 0.0  # zero in the first 9 columns only when they are all that count
    for cols, weight in ((12, 1.0), (9, 0.37)):
        start = rng.normal(size=(7, 7))
        expected, got = start.copy(), start.copy()
        _dense_sandwich(F, M, 7, cols, weight, expected)
        _add_sandwich(F, M, 7, cols, weight, got, np.empty((7, 12)), np.empty(7, np.bool_))
        np.testing.assert_array_equal(got, expected)


def test_group_moments_are_the_pairwise_sums_in_pair_order_bit_for_bit():
    """Each moment entry equals the sum over its group's pairs, in their order from +0, of the
    products that define it (written out pair by pair in Python floats), bit for bit; pairs of
    different groups interleave."""
    from isf.fitting.moment_kernels import group_moments
    rng = np.random.default_rng(3)
    n_fits, n_links, K = 3, 2, 90
    fit, link = rng.integers(0, n_fits, K), rng.integers(0, n_links, K)
    x, m = rng.normal(scale=0.03, size=(K, 3)), rng.normal(size=(K, 3))
    q, n = rng.normal(scale=0.05, size=(K, 3)) + 0.5, rng.normal(size=(K, 3))
    origin, fit_count, M, N, v, beta2, w, s, count = group_moments(fit, link, x, m, q, n, n_fits, n_links)
    for g in range(n_fits * n_links):
        b = g // n_links
        ks = [k for k in range(K) if fit[k] == b and link[k] == g % n_links]
        expected = {name: np.zeros(shape) for name, shape in
                    (("M", (12, 12)), ("N", (9, 9)), ("v", 12), ("w", 9), ("s", 4))}
        expected_beta2 = 0.0
        for k in ks:
            beta = 0.0
            for j in range(3):
                beta += (float(q[k, j]) - float(origin[b, j])) * float(n[k, j])
            y = [float(x[k, i]) * float(n[k, j]) for i in range(3) for j in range(3)] + list(map(float, n[k]))
            u = [float(m[k, i]) * float(n[k, j]) for i in range(3) for j in range(3)]
            for i in range(12):
                expected["v"][i] += beta * y[i]
                for j in range(12):
                    expected["M"][i, j] += y[min(i, j)] * y[max(i, j)]
            for i in range(9):
                expected["w"][i] += u[i]
                for j in range(9):
                    expected["N"][i, j] += u[min(i, j)] * u[max(i, j)]
            expected_beta2 += beta * beta
            expected["s"] += [*x[k], 1.0]
        for name, got in (("M", M), ("N", N), ("v", v), ("w", w), ("s", s)):
            np.testing.assert_array_equal(got[g], expected[name], err_msg=name)
        assert beta2[g] == expected_beta2 and count[g] == len(ks)
    np.testing.assert_array_equal(fit_count, np.bincount(fit, minlength=n_fits))
