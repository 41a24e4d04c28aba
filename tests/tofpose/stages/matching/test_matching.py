import numpy as np
import pytest

from tofpose.config import MatchingConfig
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.stages.matching.matching import match_reflectors, one_to_one, pair_compatibility


def _observe(ids, noise_mm=1.0, seed=0, distance_mm=3000.0):
    cat = paper_target()
    R = rotation_from_euler_deg(4, -6, 25) @ R_FACING
    t = np.array([40.0, -20.0, distance_mm])
    rng = np.random.default_rng(seed)
    idx = [int(np.flatnonzero(cat.ids == i)[0]) for i in ids]
    y = cat.positions_mm[idx] @ R.T + t + rng.normal(0, noise_mm, (len(idx), 3))
    return cat, y, idx


def _pairs_as_ids(cat, res):
    return {int(k): int(cat.ids[i]) for k, i in res.pairs}


@pytest.mark.parametrize(
    "ids", [[1, 2, 3, 4, 5, 6, 7, 8], [3, 4, 5, 6, 7], [5, 6, 7, 8], [2, 4, 6]]
)
def test_recovers_correspondence_with_markers_out_of_view(ids):
    cat, y, idx = _observe(ids)
    perm = np.random.default_rng(1).permutation(len(ids))
    res = match_reflectors(y[perm], cat.positions_mm)
    assert res.ok, res.reason
    assert _pairs_as_ids(cat, res) == {k: ids[p] for k, p in enumerate(perm)}


@pytest.mark.parametrize("n_spurious", [1, 3, 6])
def test_spurious_blobs_end_unmatched_after_annealing_and_the_residual_check(n_spurious):
    ids = [2, 3, 4, 5, 6, 7]
    cat, y, idx = _observe(ids, seed=n_spurious)
    rng = np.random.default_rng(10 + n_spurious)
    # Spurious bright blobs on and around the target plane.
    fake = y.mean(axis=0) + rng.uniform([-500, -300, -80], [500, 300, 80], (n_spurious, 3))
    obs = np.vstack((y, fake))
    res = match_reflectors(obs, cat.positions_mm)
    assert res.ok, res.reason
    assert _pairs_as_ids(cat, res) == {k: ids[k] for k in range(len(ids))}
    assert set(range(len(ids), len(obs))) <= set(res.unmatched)
    # what annealing itself does: each true blob's most probable label is its own
    # reflector; a spurious blob is often drawn to a reflector too (its pair distances
    # fit by chance), and it is the one-to-one assignment and the rigid residual check
    # after annealing that leave it unmatched
    best = res.A.argmax(axis=1)
    assert [int(cat.ids[b - 1]) for b in best[: len(ids)]] == ids


def test_inconsistent_observations_are_refused_not_matched():
    cat = paper_target()
    rng = np.random.default_rng(4)
    junk = rng.uniform([-600, -400, 2800], [600, 400, 3200], (6, 3))
    res = match_reflectors(junk, cat.positions_mm)
    assert not res.ok
    assert "no rigidly consistent match" in res.reason or len(res.pairs) == 0


def test_too_few_candidates_reason():
    cat, y, _ = _observe([5, 6])
    res = match_reflectors(y, cat.positions_mm)
    assert not res.ok and "need 3" in res.reason


def test_pair_compatibility_is_eq36_potential():
    cat, y, idx = _observe([1, 2, 3], noise_mm=0.0)
    P = pair_compatibility(y, cat.positions_mm, alpha_mm=10.0, clip_factor=1e9)
    # correct pairs (k -> idx[k], l -> idx[l]) have rho = 0: potential -alpha^2
    assert P[0, idx[0], 1, idx[1]] == pytest.approx(-100.0, abs=1e-6)
    d_obs = np.linalg.norm(y[0] - y[1])
    d_cat = np.linalg.norm(cat.positions_mm[idx[0]] - cat.positions_mm[4])
    assert P[0, idx[0], 1, 4] == pytest.approx((d_obs - d_cat) ** 2 - 100.0)
    assert P[0, 0, 0, 1] == 0.0  # l == k: no self-support


def test_one_to_one_resolves_duplicate_row_maxima():
    A = np.array([[0.1, 0.8, 0.1], [0.1, 0.7, 0.2]])  # both rows prefer catalog 0
    pairs, unmatched = one_to_one(A)
    assert sorted(map(tuple, pairs.tolist())) == [(0, 0), (1, 1)]
    assert unmatched == []


@pytest.mark.parametrize("seed", range(12))
def test_size_term_decides_a_mirror_symmetric_target(seed):
    """A kite symmetric about its y axis: swapping the two side markers keeps every pair
    distance (the swap is a 180 deg turn about y), so distances alone cannot tell them
    apart; their sizes (35 vs 80 mm) can. Without sizes the match is the mirror in 7 of
    these 12 shuffles; with sizes it is right in all."""
    cat = np.array([[-100.0, 0, 0], [100.0, 0, 0], [0, 150.0, 0], [0, -60.0, 0]])
    diam = np.array([35.0, 80.0, 50.0, 50.0])
    R = rotation_from_euler_deg(3, -4, 10) @ R_FACING
    rng = np.random.default_rng(seed)
    perm = rng.permutation(4)
    y = (cat @ R.T + np.array([20.0, 10.0, 3000.0]) + rng.normal(0, 1.0, (4, 3)))[perm]
    seen_diam = diam[perm] * rng.uniform(0.9, 1.1, 4)
    truth = {k: int(perm[k]) for k in range(4)}
    res = match_reflectors(
        y, cat, MatchingConfig(), observed_diameter_mm=seen_diam, catalog_diameter_mm=diam
    )
    assert res.ok and {int(k): int(i) for k, i in res.pairs} == truth


def test_without_sizes_the_kite_is_ambiguous():
    """The control for the test above: without the size term some shuffles get the
    mirror assignment, so the size term is what decides there."""
    cat = np.array([[-100.0, 0, 0], [100.0, 0, 0], [0, 150.0, 0], [0, -60.0, 0]])
    R = rotation_from_euler_deg(3, -4, 10) @ R_FACING
    mirrored = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        perm = rng.permutation(4)
        y = (cat @ R.T + np.array([20.0, 10.0, 3000.0]) + rng.normal(0, 1.0, (4, 3)))[perm]
        res = match_reflectors(y, cat, MatchingConfig())
        mirrored += {int(k): int(i) for k, i in res.pairs} != {k: int(perm[k]) for k in range(4)}
    assert mirrored >= 3


def test_triplet_fallback_respects_the_pose_constraint():
    """With the facing constraint, the triplet search returns the true (not mirror) pose."""
    from tofpose.stages.matching.matching import match_by_triplets

    ids = [5, 6, 7]
    cat, y, idx = _observe(ids, noise_mm=0.5, seed=3, distance_mm=10000.0)

    facing = (cat.positions_mm.mean(axis=0), 0.0)  # the target's front towards the camera
    pairs = match_by_triplets(y, cat.positions_mm, 20.0, np.full(3, 20.0), facing)
    assert {int(k): int(cat.ids[i]) for k, i in pairs} == {0: 5, 1: 6, 2: 7}
    unconstrained = match_by_triplets(y, cat.positions_mm, 20.0, np.full(3, 20.0))
    assert len(unconstrained) == 3
    impossible = (cat.positions_mm.mean(axis=0), 1.5)  # no pose has a cosine above 1
    assert len(match_by_triplets(y, cat.positions_mm, 20.0, np.full(3, 20.0), impossible)) == 0


def test_ransac_trials_needed_is_the_standard_count():
    from math import comb, log

    from tofpose.stages.matching.matching import ransac_trials_needed

    assert ransac_trials_needed(2, 10, 0.99) == float("inf")  # no hypothesis yet
    assert ransac_trials_needed(8, 8, 0.99) == 1.0  # every triplet is all-marker
    p = comb(8, 3) / comb(18, 3)
    assert ransac_trials_needed(8, 18, 0.99) == pytest.approx(log(0.01) / log(1 - p))


def test_ransac_to_confidence_stops_early_and_finds_the_markers():
    """With 8 markers among 14 blobs, the confidence rule stops long before all 364
    triplets and still returns the right correspondence."""
    from tofpose.core.catalog import paper_target
    from tofpose.stages.matching.matching import match_by_triplets, random_triplets

    rng = np.random.default_rng(3)
    cat = paper_target().positions_mm
    R = np.eye(3)
    t = np.array([10.0, -20.0, 3000.0])
    markers = cat @ R.T + t
    spurious = t + rng.uniform([-700, -450, -150], [700, 450, 250], size=(6, 3))
    observed = np.vstack([markers, spurious])
    order = rng.permutation(len(observed))
    observed = observed[order]
    stats: dict = {}
    pairs = match_by_triplets(
        observed,
        cat,
        15.0,
        np.full(len(observed), 15.0),
        None,
        max_observed=len(observed),
        observed_triplets=random_triplets(len(observed), rng),
        confidence=0.99,
        stats=stats,
    )
    assert stats["triplets"] < 60  # log(0.01) / log(1 - 56/364) = 28 once all 8 are found
    truth = {int(np.flatnonzero(order == i)[0]): i for i in range(len(cat))}
    assert {int(k): int(i) for k, i in pairs} == truth
