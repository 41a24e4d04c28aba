"""The triplet-hypothesis kernel against a plain NumPy/SciPy statement of the search
(``matching.match_by_triplets``' docstring), on scenes with spurious points."""

from __future__ import annotations

from itertools import combinations, permutations

import numpy as np
from scipy.optimize import linear_sum_assignment

from tofpose.catalog import paper_target
from tofpose.geometry import rotation_from_euler_deg
from tofpose.kernels.pose import absolute_orientation
from tofpose.kernels.triplets import catalog_triplets
from tofpose.matching import match_by_triplets


def _reference(observed, catalog, alpha, tol, centroid, cos_min, w, max_observed=7):
    """Every observed triplet x every ordered catalog triplet of equal sides: pose,
    facing constraint, one-to-one assignment of all points, inliers within tol; the
    most inliers win, then the least sum of w d^2."""
    best, best_key = np.empty((0, 2), int), (0, np.inf)
    g = min(len(observed), max_observed)
    for a, b, c in combinations(range(g), 3):
        o = [np.linalg.norm(observed[u] - observed[v]) for u, v in ((a, b), (b, c), (a, c))]
        for i, j, k in permutations(range(len(catalog)), 3):
            s = [np.linalg.norm(catalog[u] - catalog[v]) for u, v in ((i, j), (j, k), (i, k))]
            if not np.all(np.abs(np.subtract(s, o)) <= alpha):
                continue
            R, t = absolute_orientation(catalog[[i, j, k]], observed[[a, b, c]], w[[a, b, c]])
            to_camera = -(R @ centroid + t)
            if R[:, 2] @ to_camera / np.linalg.norm(to_camera) < cos_min:
                continue
            dist = np.linalg.norm(observed[:, None] - (catalog @ R.T + t)[None], axis=-1)
            rows, cols = linear_sum_assignment(dist)
            ok = dist[rows, cols] <= tol[rows]
            key = (int(ok.sum()), float((dist[rows, cols][ok] ** 2 * w[rows[ok]]).sum()))
            if key[0] >= 3 and (key[0] > best_key[0]
                                or (key[0] == best_key[0] and key[1] < best_key[1])):  # fmt: skip
                best, best_key = np.column_stack((rows[ok], cols[ok])), key
    return best


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
