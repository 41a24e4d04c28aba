"""The reference statement of §4 against known truth: the oracle must itself be right."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from tofpose.config import MatchingConfig
from tofpose.core.catalog import paper_target
from tofpose.stages.matching.reference import matching as reference
from tofpose.stages.pose.reference.pose import absolute_orientation


def _scene(seed, n_spurious=2, noise_mm=2.0):
    """The paper target's reflectors under a random pose at ~4 m with noise, in a shuffled
    order, plus spurious points: (observed (g, 3), true catalog index per blob or -1)."""
    rng = np.random.default_rng(seed)
    x = paper_target().positions_mm
    R = Rotation.from_euler("xyz", rng.uniform(-30, 30, 3), degrees=True).as_matrix()
    y = x @ R.T + [100.0, -50.0, 4000.0] + rng.normal(0, noise_mm, x.shape)
    spurious = rng.uniform([-600, -400, 3500], [600, 400, 4500], (n_spurious, 3))
    observed = np.vstack((y, spurious))
    truth = np.concatenate((np.arange(len(x)), np.full(n_spurious, -1)))
    order = rng.permutation(len(observed))
    return observed[order], truth[order]


def test_annealing_and_the_one_to_one_step_find_every_reflector_and_no_spurious_blob():
    cfg = MatchingConfig()
    x = paper_target().positions_mm
    for seed in range(5):
        observed, truth = _scene(seed)
        alpha = cfg.alpha_for(observed)
        P = reference.pair_potentials(observed, x, alpha, cfg.clip_factor)
        unary = np.zeros((len(observed), len(x)))
        A, iterations = reference.anneal(
            P, unary, cfg.psi_start / alpha**2, cfg.psi_end / alpha**2, cfg.growth
        )
        # psi grows from psi_start to psi_end by the factor growth (Eq. 35)
        assert (
            iterations
            == int(np.floor(np.log(cfg.psi_end / cfg.psi_start) / np.log(cfg.growth))) + 1
        )
        np.testing.assert_allclose(A.sum(axis=1), 1.0, atol=1e-12)
        pairs, unmatched = reference.one_to_one(A)
        assert {(int(k), int(i)) for k, i in pairs} == {
            (k, int(truth[k])) for k in range(len(truth)) if truth[k] >= 0
        }
        assert unmatched == sorted(np.flatnonzero(truth < 0).tolist())


def test_pair_potentials_reward_consistent_pairs_and_ignore_self_pairs():
    """Eq. 36 on three points: a pair whose distances agree costs -alpha^2, one off by
    more than clip * alpha costs (clip^2 - 1) alpha^2, and self-pairs 0."""
    catalog = np.array([[0.0, 0, 0], [100, 0, 0], [0, 50, 0]])
    observed = catalog + [0, 0, 1000.0]
    observed[2] = [0.0, 90.0, 1000.0]  # 40 mm further from point 0 than reflector 2 is
    P = reference.pair_potentials(observed, catalog, 10.0, 2.0)
    assert P[0, 0, 1, 1] == -100.0  # |100 - 100| = 0
    assert P[0, 0, 2, 2] == 300.0  # rho = 40 clipped at 20: 400 - 100
    assert P[0, 0, 0, 1] == 0.0 and P[0, 0, 1, 0] == 0.0


def test_the_rigid_residual_check_drops_a_planted_wrong_pair_first():
    x = paper_target().positions_mm
    R = Rotation.from_euler("xyz", [10, -5, 20], degrees=True).as_matrix()
    y = x @ R.T + [0.0, 0.0, 3000.0]
    pairs = np.column_stack((np.arange(8), np.arange(8)))
    pairs[3, 1], pairs[5, 1] = 5, 3  # two blobs swapped
    kept, rejected, ok = reference.rigid_residual_check(y, x, pairs, np.ones(8), np.full(8, 5.0), 3)
    assert ok and sorted(rejected) == [3, 5] and len(kept) == 6
    R_fit, _ = absolute_orientation(x[kept[:, 1]], y[kept[:, 0]], np.ones(6))
    np.testing.assert_allclose(R_fit, R, atol=1e-9)
    _, rejected, ok = reference.rigid_residual_check(
        y[:3] + [[0, 0, 0], [0, 0, 0], [90, 0, 0]], x, pairs[:3], np.ones(8), np.full(8, 5.0), 3
    )
    assert not ok and sorted(rejected) == [0, 1, 2]
