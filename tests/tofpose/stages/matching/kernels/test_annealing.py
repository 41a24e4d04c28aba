"""The compiled annealing iteration, pair potentials, size term and one-to-one step
against Eqs. 25-39 as ``tofpose.stages.matching.reference.matching`` states them."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.config import MatchingConfig
from tofpose.stages.matching.kernels.annealing import anneal_assignment, pair_potentials
from tofpose.stages.matching.matching import pair_compatibility
from tofpose.stages.matching.reference import matching as reference


def test_anneal_assignment_equals_the_equations():
    rng = np.random.default_rng(0)
    catalog = rng.uniform(-300, 300, (8, 3))
    observed = np.vstack(
        (catalog[[0, 2, 3, 5, 6]] + rng.normal(0, 2, (5, 3)), rng.uniform(-300, 300, (2, 3)))
    )
    cfg = MatchingConfig()
    alpha = 15.0
    P = pair_compatibility(observed, catalog, alpha, cfg.clip_factor)
    u = rng.uniform(0, 50, (7, 8))
    args = (cfg.psi_start / alpha**2, cfg.psi_end / alpha**2, cfg.growth)
    A, it = anneal_assignment(np.ascontiguousarray(P.reshape(56, 56)), u, *args)
    A_ref, it_ref = reference.anneal(P, u, *args)
    assert it == it_ref > 30
    np.testing.assert_allclose(A, A_ref, atol=1e-12)
    assert [int(np.argmax(A[k])) for k in range(5)] == [1, 3, 4, 6, 7]  # markers found


@pytest.mark.parametrize("clip", [3.0, 1e9])
def test_pair_potentials_equal_the_broadcast_equation(clip):
    rng = np.random.default_rng(3)
    observed, catalog = rng.uniform(-400, 400, (7, 3)), rng.uniform(-300, 300, (8, 3))
    got = pair_potentials(observed, catalog, 12.5, clip)
    np.testing.assert_array_equal(got, reference.pair_potentials(observed, catalog, 12.5, clip))


def test_size_term_equals_the_numpy_statement_and_its_special_cases():
    """``matching.size_unary`` (compiled) against (ln(d / D) / ln 1.6)^2 capped at 4,
    undefined -> 0; NumPy's vectorised log may differ from libm's by one ulp."""
    from tofpose.stages.matching.matching import size_unary

    rng = np.random.default_rng(0)
    catalog = np.array([35.0, 50.0, 80.0, 20.0])
    observed = rng.uniform(5.0, 150.0, 200)
    want = reference.size_mismatch(observed, catalog)
    np.testing.assert_allclose(size_unary(observed, catalog), want, rtol=1e-14, atol=1e-15)
    odd = np.array([np.nan, 0.0, np.inf, 56.0, 35.0 * 1.6**3])
    for special in (size_unary(odd, catalog[:1]), reference.size_mismatch(odd, catalog[:1])):
        np.testing.assert_allclose(special[:, 0], [0.0, 4.0, 4.0, 1.0, 4.0], rtol=1e-12)


def test_one_to_one_is_the_hungarian_assignment_with_private_null_columns():
    """The compiled cost matrix and reading of the assignment against the reference's,
    on random assignment matrices with blobs that prefer the null label and blobs
    competing for one reflector."""
    from tofpose.stages.matching.matching import one_to_one

    rng = np.random.default_rng(8)
    for _ in range(300):
        g, e = int(rng.integers(1, 12)), int(rng.integers(3, 10))
        A = rng.dirichlet(np.full(e + 1, 0.3), size=g)
        A[rng.random(g) < 0.2, 0] = 5.0  # some blobs clearly spurious
        A /= A.sum(axis=1, keepdims=True)
        want_pairs, want_unmatched = reference.one_to_one(A)
        pairs, unmatched = one_to_one(A)
        np.testing.assert_array_equal(pairs, want_pairs)
        assert unmatched == want_unmatched
        assert len(set(pairs[:, 1].tolist())) == len(pairs)  # one blob per reflector


@pytest.mark.parametrize("use_size", [True, False])
def test_soft_assignment_is_potentials_size_term_and_annealing_in_one(use_size):
    """The one-call soft assignment gives exactly what pair_potentials, size_mismatch
    and anneal_assignment give one after the other (and what the reference's equations
    give, to rounding), with and without the size term; the size term changes A."""
    from tofpose.stages.matching.kernels.annealing import size_mismatch, soft_assignment

    rng = np.random.default_rng(5)
    catalog = rng.uniform(-300, 300, (8, 3))
    observed = np.vstack(
        (catalog[[1, 2, 4, 7]] + rng.normal(0, 2, (4, 3)), rng.uniform(-300, 300, (2, 3)))
    )
    cat_d = rng.uniform(30, 80, 8)
    obs_d = np.concatenate((cat_d[[1, 2, 4, 7]] * 1.05, [np.nan, 200.0]))
    cfg, alpha = MatchingConfig(), 14.0
    scale = cfg.size_weight * alpha**2
    psi = (cfg.psi_start / alpha**2, cfg.psi_end / alpha**2, cfg.growth)
    args = (observed, catalog, alpha, cfg.clip_factor, use_size, obs_d, cat_d, scale, *psi)
    A, it = soft_assignment(*args)
    P = pair_potentials(observed, catalog, alpha, cfg.clip_factor)
    u = scale * size_mismatch(obs_d, cat_d) if use_size else np.zeros((6, 8))
    A_steps, it_steps = anneal_assignment(np.ascontiguousarray(P.reshape(48, 48)), u, *psi)
    assert it == it_steps > 30
    np.testing.assert_array_equal(A, A_steps)
    A_ref, it_ref = reference.soft_assignment(*args)
    assert it_ref == it
    np.testing.assert_allclose(A, A_ref, atol=1e-12)
    assert [int(np.argmax(A[k])) for k in range(4)] == [2, 3, 5, 8]  # markers found
    A_other, _ = soft_assignment(*args[:4], not use_size, *args[5:])
    assert not np.array_equal(A, A_other)
