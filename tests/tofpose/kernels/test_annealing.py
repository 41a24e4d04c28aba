"""The compiled annealing iteration and pair potentials against Eqs. 35-39 written in NumPy."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.config import MatchingConfig
from tofpose.kernels.annealing import anneal_assignment, pair_potentials
from tofpose.matching import pair_compatibility


def _reference(P, u, psi, psi_end, growth):
    g, e = u.shape
    A = np.full((g, e + 1), 1.0 / (1 + e))  # Eq. 39
    Pm = P.reshape(g * e, g * e)
    it = 0
    while psi <= psi_end:
        E = (Pm @ A[:, 1:].reshape(-1)).reshape(g, e) + u
        logits = np.concatenate((np.zeros((g, 1)), -psi * E), axis=1)  # F_k0 = 1 (Eq. 36)
        logits -= logits.max(axis=1, keepdims=True)
        F = np.exp(logits)
        A = F / F.sum(axis=1, keepdims=True)  # Eq. 37
        psi *= growth  # Eq. 35
        it += 1
    return A, it


def test_anneal_assignment_equals_the_equations():
    rng = np.random.default_rng(0)
    catalog = rng.uniform(-300, 300, (8, 3))
    observed = np.vstack((catalog[[0, 2, 3, 5, 6]] + rng.normal(0, 2, (5, 3)),
                          rng.uniform(-300, 300, (2, 3))))  # fmt: skip
    cfg = MatchingConfig()
    alpha = 15.0
    P = pair_compatibility(observed, catalog, alpha, cfg.clip_factor)
    u = rng.uniform(0, 50, (7, 8))
    args = (cfg.psi_start / alpha**2, cfg.psi_end / alpha**2, cfg.growth)
    A, it = anneal_assignment(np.ascontiguousarray(P.reshape(56, 56)), u, *args)
    A_ref, it_ref = _reference(P, u, *args)
    assert it == it_ref > 30
    np.testing.assert_allclose(A, A_ref, atol=1e-12)
    assert [int(np.argmax(A[k])) for k in range(5)] == [1, 3, 4, 6, 7]  # markers found


def _potentials_numpy(observed, catalog, alpha, clip):
    """Eq. 36 by broadcasting (the NumPy form the kernel replaced)."""
    o = np.linalg.norm(observed[:, None] - observed[None], axis=-1)  # Eq. 26
    c = np.linalg.norm(catalog[:, None] - catalog[None], axis=-1)  # Eq. 25
    rho = np.abs(o[:, None, :, None] - c[None, :, None, :])  # (k, i, l, j)
    P = np.minimum(rho**2, (clip * alpha) ** 2) - alpha**2
    g, e = len(observed), len(catalog)
    P[np.arange(g), :, np.arange(g), :] = 0.0
    P[:, np.arange(e), :, np.arange(e)] = 0.0
    return P


@pytest.mark.parametrize("clip", [3.0, 1e9])
def test_pair_potentials_equal_the_broadcast_equation(clip):
    rng = np.random.default_rng(3)
    observed, catalog = rng.uniform(-400, 400, (7, 3)), rng.uniform(-300, 300, (8, 3))
    got = pair_potentials(observed, catalog, 12.5, clip)
    np.testing.assert_array_equal(got, _potentials_numpy(observed, catalog, 12.5, clip))


def test_size_term_equals_the_numpy_statement_and_its_special_cases():
    """``matching.size_unary`` (compiled) against (ln(d / D) / ln 1.6)^2 capped at 4,
    undefined -> 0; NumPy's vectorised log may differ from libm's by one ulp."""
    from tofpose.matching import size_unary

    rng = np.random.default_rng(0)
    catalog = np.array([35.0, 50.0, 80.0, 20.0])
    observed = rng.uniform(5.0, 150.0, 200)
    want = np.minimum((np.log(observed[:, None] / catalog[None]) / np.log(1.6)) ** 2, 4.0)
    np.testing.assert_allclose(size_unary(observed, catalog), want, rtol=1e-14, atol=1e-15)
    special = size_unary(np.array([np.nan, 0.0, np.inf, 56.0, 35.0 * 1.6**3]), catalog[:1])
    np.testing.assert_allclose(special[:, 0], [0.0, 4.0, 4.0, 1.0, 4.0], rtol=1e-12)


def test_one_to_one_is_the_hungarian_assignment_with_private_null_columns():
    """The compiled cost matrix and reading of the assignment against the same step in
    NumPy (the form they replaced), on random assignment matrices with blobs that prefer
    the null label and blobs competing for one reflector."""
    from scipy.optimize import linear_sum_assignment

    from tofpose.matching import one_to_one

    rng = np.random.default_rng(8)
    for _ in range(300):
        g, e = int(rng.integers(1, 12)), int(rng.integers(3, 10))
        A = rng.dirichlet(np.full(e + 1, 0.3), size=g)
        A[rng.random(g) < 0.2, 0] = 5.0  # some blobs clearly spurious
        A /= A.sum(axis=1, keepdims=True)
        cost = np.full((g, e + g), 1e6)
        log_a = -np.log(np.maximum(A, 1e-300))
        cost[:, :e] = log_a[:, 1:]
        np.fill_diagonal(cost[:, e:], log_a[:, 0])
        rows, cols = linear_sum_assignment(cost)
        real = (cols < e) & (cost[rows, cols] < 1e6)
        pairs, unmatched = one_to_one(A)
        np.testing.assert_array_equal(pairs, np.column_stack((rows[real], cols[real])))
        assert unmatched == sorted(set(range(g)) - set(rows[real].tolist()))
        assert len(set(pairs[:, 1].tolist())) == len(pairs)  # one blob per reflector
