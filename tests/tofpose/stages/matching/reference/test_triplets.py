"""The reference statement of the triplet hypotheses
(``tofpose.stages.matching.reference.triplets``)
against the compiled search (``tofpose.stages.matching.kernels.triplets``) on random scenes with
spurious
points, and against known truth.

Equality: ``catalog_triplets``' triplets and the search's best pairs, inlier count,
triplets tried and stop flag exact; ``trials_needed`` to 1e-14 relative (NumPy's log
against the compiled one: an ulp), side lengths to 1e-15 relative (one rounding of a
3-vector's norm) and the best hypothesis' cost to 1e-9 relative (the
kernel's SVD and assignment against LAPACK's and SciPy's)."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest

from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.matching.kernels import triplets as kernel
from tofpose.stages.matching.records import TripletBest, TripletProblem, TripletRule
from tofpose.stages.matching.reference import triplets as reference

CATALOG = paper_target().positions_mm
CENTROID = CATALOG.mean(axis=0)


def _scene(rng, n_spurious_max=5, noise_mm=2.0):
    """A facing pose's rigid copy of a random subset (3..8) of the paper target with
    noise, spurious points about the target, shuffled: (observed (n, 3), truth (n,) the
    catalog index of each point or -1)."""
    R = rotation_from_euler_deg(180 + rng.uniform(-30, 30), *rng.uniform(-30, 30, 2))
    t = np.array([*rng.uniform(-300, 300, 2), rng.uniform(1500, 8000)])
    seen = rng.choice(len(CATALOG), rng.integers(3, len(CATALOG) + 1), replace=False)
    markers = CATALOG[seen] @ R.T + t + rng.normal(0, noise_mm, (len(seen), 3))
    n_spurious = rng.integers(0, n_spurious_max + 1)
    spurious = t + rng.uniform([-700, -450, -150], [700, 450, 250], (n_spurious, 3))
    order = rng.permutation(len(seen) + n_spurious)
    truth = np.concatenate((seen, np.full(n_spurious, -1)))[order]
    return np.vstack([markers, spurious])[order], truth


def _search(module, observed, triplets, cos_min=None, confidence=None, w=None, start=None):
    """``module.triplet_search`` over ``triplets`` as ``match_by_triplets`` calls it
    (alpha 12 mm, tolerance 15 mm, at least 3 inliers), from ``start`` (best, best_n,
    best_cost, tried) or from nothing: (best, best_n, best_cost, tried, done)."""
    n = len(observed)
    w = np.ones(n) if w is None else w
    tri, sides = module.catalog_triplets(CATALOG)
    rule = (  # TripletRule's fields, in order
        cos_min is not None,
        CENTROID,
        -np.inf if cos_min is None else float(cos_min),
        3,
        confidence is not None,
        0.0 if confidence is None else float(confidence),
    )
    start = (np.empty((0, 2), np.int64), 0, np.inf, 0) if start is None else start
    problem = TripletProblem(
        observed=observed,
        catalog=CATALOG,
        weights=w,
        tol_mm=np.full(n, 15.0),
        alpha_mm=12.0,
        cat_tri=tri,
        cat_sides=sides,
    )
    triplets = np.ascontiguousarray(triplets, np.int64)
    best, done = module.triplet_search(problem, triplets, TripletRule(*rule), TripletBest(*start))
    return (*best, done)


def _assert_same(got, want):
    np.testing.assert_array_equal(np.asarray(got[0]).reshape(-1, 2), want[0].reshape(-1, 2))
    assert got[1] == want[1] and got[3] == want[3] and got[4] == want[4]
    assert got[2] == pytest.approx(want[2], rel=1e-9) or got[2] == want[2] == np.inf


def test_catalog_triplets_equal_the_kernel():
    rng = np.random.default_rng(2)
    for catalog in (CATALOG, rng.uniform(-400, 400, (5, 3)), CATALOG[:3], CATALOG[:2]):
        tri, sides = reference.catalog_triplets(catalog)
        want_tri, want_sides = kernel.catalog_triplets(np.ascontiguousarray(catalog))
        np.testing.assert_array_equal(tri, want_tri)
        np.testing.assert_allclose(sides, want_sides, rtol=1e-15, atol=0)
        assert len(tri) == len(catalog) * (len(catalog) - 1) * (len(catalog) - 2)


def test_trials_needed_equals_the_kernel_and_the_count():
    for n in range(0, 16):
        for i in range(0, n + 1):
            for p in (0.9, 0.99, 0.999):
                want = kernel.trials_needed(i, n, p)
                assert reference.trials_needed(i, n, p) == pytest.approx(want, rel=1e-14)
    # 4 markers among 8 blobs: 4 of the 56 triplets are all markers
    assert reference.trials_needed(4, 8, 0.99) == pytest.approx(np.log(0.01) / np.log(52 / 56))
    assert reference.trials_needed(5, 5, 0.99) == 1.0
    assert reference.trials_needed(2, 8, 0.99) == np.inf


@pytest.mark.parametrize("facing_deg", [None, 75.0, 20.0])
def test_the_search_equals_the_kernel_on_random_scenes(facing_deg):
    """Every triplet of the first 7 points, with random weights, without the facing
    constraint, with a view angle of at most 75 deg and of at most 20 deg (which refuses
    some true poses: the scenes are tilted up to ~40 deg)."""
    rng = np.random.default_rng(8)
    found = 0
    for _ in range(25):
        observed, _ = _scene(rng)
        w = rng.uniform(0.5, 2.0, len(observed))
        triplets = list(combinations(range(min(len(observed), 7)), 3))
        cos_min = None if facing_deg is None else np.cos(np.radians(facing_deg))
        want = _search(kernel, observed, triplets, cos_min, w=w)
        _assert_same(_search(reference, observed, triplets, cos_min, w=w), want)
        found += want[1] >= 3
    assert found > (10 if facing_deg == 20.0 else 20)  # not a comparison of two empties


def test_the_ransac_search_equals_the_kernel_in_chunks_with_its_stopping_rule():
    """Random triplet orders over all points with the confidence rule, the search
    continued chunk by chunk from its own best (as ``match_by_triplets`` with a
    deadline): the same best, the same number tried and the same stop."""
    rng = np.random.default_rng(11)
    stopped = 0
    for _ in range(20):
        observed, _ = _scene(rng, n_spurious_max=6)
        triplets = np.array(list(combinations(range(len(observed)), 3)), np.int64)
        triplets = triplets[rng.permutation(len(triplets))]
        got = want = (np.empty((0, 2), np.int64), 0, np.inf, 0)
        for s in range(0, len(triplets), 4):
            want = _search(kernel, observed, triplets[s : s + 4], confidence=0.99, start=want[:4])
            got = _search(reference, observed, triplets[s : s + 4], confidence=0.99, start=got[:4])
            _assert_same(got, want)
            if want[4]:
                stopped += 1
                break
    assert stopped > 10  # the rule does end searches


def test_the_search_finds_the_true_correspondences():
    """A noisy (2 mm) rigid copy of the paper target with spurious points: every marker
    matched to its own reflector, no spurious point matched."""
    rng = np.random.default_rng(5)
    for _ in range(10):
        observed, truth = _scene(rng)
        best, best_n, _, tried, done = _search(
            reference, observed, list(combinations(range(len(observed)), 3)), np.cos(np.radians(75))
        )
        assert not done and tried == len(list(combinations(range(len(observed)), 3)))
        assert best_n == (truth >= 0).sum()
        assert {(int(k), int(i)) for k, i in best} == {
            (k, int(truth[k])) for k in range(len(truth)) if truth[k] >= 0
        }
