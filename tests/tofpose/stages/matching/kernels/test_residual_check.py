"""The compiled rigid residual check of §4 (``kernels.residual_check.prune_pairs``,
behind ``matching.rigid_residual_check``) against ``tofpose.stages.matching.reference.matching``'s,
on random
rigid scenes with planted wrong pairs; and the wrong pairs are the ones dropped."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.matching.matching import rigid_residual_check
from tofpose.stages.matching.reference.matching import rigid_residual_check as reference_check


@pytest.mark.parametrize("n_wrong", [0, 1, 2, 4])
def test_pruned_pairs_equal_the_reference_and_drop_the_planted_wrong_pairs(n_wrong):
    rng = np.random.default_rng(n_wrong)
    found_planted = scenes = 0
    for _ in range(200):
        e = int(rng.integers(4, 10))
        catalog = rng.uniform(-200, 200, (e, 3))
        R = rotation_from_euler_deg(*rng.uniform(-40, 40, 3))
        observed = catalog @ R.T + [30.0, -20.0, 2500.0] + rng.normal(0, 0.5, (e, 3))
        pairs = np.column_stack((np.arange(e), np.arange(e)))
        wrong = rng.choice(e, size=min(n_wrong, e), replace=False)
        observed[wrong] += rng.normal(0, 60.0, (len(wrong), 3))  # far from its reflector
        weights = rng.uniform(0.5, 2.0, e)
        tol = np.full(e, 4.0)
        kept, rejected, reason = rigid_residual_check(observed, catalog, pairs, weights, tol, 3)
        want_kept, want_rej, ok = reference_check(observed, catalog, pairs, weights, tol, 3)
        np.testing.assert_array_equal(kept, want_kept)
        assert rejected == want_rej and (reason == "") == ok
        if e - n_wrong >= 5:
            scenes += 1
            found_planted += ok and set(rejected) == set(wrong.tolist())
    # with five or more right pairs the check drops exactly the planted wrong ones (a
    # wrong pair can drag a least-squares fit onto a right one now and then)
    assert found_planted >= 0.9 * scenes > 0


def test_too_few_pairs_are_all_rejected_with_a_reason():
    observed = np.array([[0.0, 0, 1000], [50, 0, 1000]])
    kept, rejected, reason = rigid_residual_check(
        observed, observed, np.array([[0, 0], [1, 1]]), np.ones(2), 5.0, 3
    )
    assert kept.shape == (0, 2) and rejected == [0, 1] and "no rigidly consistent" in reason
