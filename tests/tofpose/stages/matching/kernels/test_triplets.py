"""The triplet-hypothesis kernel against a plain NumPy/SciPy statement of the search
(``matching.match_by_triplets``' docstring, ``tofpose.stages.matching.reference.triplets``), on
scenes
with spurious points."""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np

from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.matching.kernels.triplets import catalog_triplets
from tofpose.stages.matching.matching import match_by_triplets
from tofpose.stages.matching.records import TripletBest, TripletProblem, TripletRule
from tofpose.stages.matching.reference import triplets as reference


def _reference(observed, catalog, alpha, tol, centroid, cos_min, w, max_observed=7):
    """Every observed triplet (of the first ``max_observed``) x every ordered catalog
    triplet of equal sides: pose, facing constraint, one-to-one assignment of all points,
    inliers within tol; the most inliers win, then the least sum of w d^2
    (``reference.triplets.triplet_search``)."""
    triplets = np.array(
        list(combinations(range(min(len(observed), max_observed)), 3)), np.int64
    ).reshape(-1, 3)
    cat_tri, cat_sides = reference.catalog_triplets(catalog)
    problem = TripletProblem(
        observed=observed,
        catalog=catalog,
        weights=w,
        tol_mm=tol,
        alpha_mm=alpha,
        cat_tri=cat_tri,
        cat_sides=cat_sides,
    )
    rule = TripletRule(
        constrain=True,
        centroid=centroid,
        cos_min=cos_min,
        min_matches=3,
        use_confidence=False,
        confidence=0.0,
    )
    start = TripletBest(pairs=np.empty((0, 2), np.int64), n_inliers=0, cost=np.inf, tried=0)
    best, _ = reference.triplet_search(problem, triplets, rule, start)
    return best.pairs


def test_catalog_triplets_in_permutation_order_with_their_sides():
    cat = paper_target().positions_mm
    tri, sides = catalog_triplets(cat)
    np.testing.assert_array_equal(tri, list(permutations(range(len(cat)), 3)))
    for (i, j, k), s in zip(tri, sides, strict=True):
        want = [np.linalg.norm(cat[u] - cat[v]) for u, v in ((i, j), (j, k), (i, k))]
        np.testing.assert_allclose(s, want, rtol=1e-15)


def test_the_search_equals_the_reference_with_spurious_points():
    cat = paper_target().positions_mm
    centroid = cat.mean(axis=0)
    rng = np.random.default_rng(8)
    found = 0
    for trial in range(40):
        R = rotation_from_euler_deg(180 + rng.uniform(-30, 30), *rng.uniform(-30, 30, 2))
        t = np.array([*rng.uniform(-300, 300, 2), rng.uniform(1500, 8000)])
        seen = rng.choice(len(cat), rng.integers(3, len(cat) + 1), replace=False)
        markers = cat[seen] @ R.T + t + rng.normal(0, 2.0, (len(seen), 3))
        spurious = t + rng.uniform([-700, -450, -150], [700, 450, 250], (rng.integers(0, 5), 3))
        observed = np.vstack([markers, spurious])[rng.permutation(len(seen) + len(spurious))]
        w = rng.uniform(0.5, 2.0, len(observed))
        tol = np.full(len(observed), 15.0)
        cos_min = 0.0 if trial % 2 else np.cos(np.radians(75))
        got = match_by_triplets(observed, cat, 12.0, tol, (centroid, cos_min), weights=w)
        want = _reference(observed, cat, 12.0, tol, centroid, cos_min, w)
        np.testing.assert_array_equal(got.reshape(-1, 2), want.reshape(-1, 2))
        found += len(want) >= 3
    assert found > 30  # the scenes are solvable: the comparison is not between two empties
