"""Triplet hypotheses as stated (ours, after §4: ``matching.match_by_triplets``, the
fallback after annealing and the RANSAC matcher): every ordered catalog triplet whose
side lengths agree with an observed triplet's, its rigid pose (Eqs. 40-50), the facing
constraint, and the inliers of the one-to-one assignment (SciPy's) of every observed
point to the predicted reflectors.

Same names, arguments and results as ``tofpose.stages.matching.kernels.triplets``. Shapes: observed
(n, 3)
mm, camera frame; catalog (e, 3) mm, target frame; pairs (k, 2) int64 (observed,
catalog).
"""

from __future__ import annotations

import math
from itertools import permutations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from tofpose.stages.matching.records import TripletBest
from tofpose.stages.pose.reference.pose import absolute_orientation, facing_cosine


def trials_needed(n_inliers, n_observed, confidence) -> float:
    """The standard RANSAC count (Fischler and Bolles 1981): observed triplets to draw
    without repetition so that one held only markers with probability ``confidence``,
    when ``n_inliers`` of ``n_observed`` blobs are markers: log(1 - p) / log(1 - q), q =
    C(I, 3) / C(n, 3) the chance a triplet is all markers; 1 when q = 1, infinite while
    fewer than 3 inliers (or blobs) are known."""
    if n_inliers < 3 or n_observed < 3:
        return np.inf
    q = math.comb(n_inliers, 3) / math.comb(n_observed, 3)
    if q >= 1.0:
        return 1.0
    return float(np.log(1.0 - confidence) / np.log(1.0 - q))


def triangle_sides(points, i, j, k) -> list[float]:
    """The side lengths (|ij|, |jk|, |ik|) of the triangle (i, j, k) of points (n, 3)."""
    return [float(np.linalg.norm(points[a] - points[b])) for a, b in ((i, j), (j, k), (i, k))]


def catalog_triplets(catalog):
    """Every ordered triplet (i, j, k) of distinct reflectors in ``itertools.permutations``
    order, (P, 3) int64, P = e (e - 1) (e - 2), and its sides ``triangle_sides``, (P, 3)
    mm."""
    tri = np.array(list(permutations(range(len(catalog)), 3)), np.int64).reshape(-1, 3)
    sides = np.array([triangle_sides(catalog, *t) for t in tri], float).reshape(-1, 3)
    return tri, sides


def hypothesis_inliers(observed, catalog, R, t, w, tol):
    """One hypothesis (R, t): each observed point assigned one-to-one to a predicted
    reflector R x_i + t (SciPy's assignment, least total distance); the pairs within
    their point's tolerance ``tol`` (n,) are the inliers. Returns the inlier pairs (k, 2)
    in observed order and their cost sum w d^2 (NumPy's sum, in that order)."""
    dist = cdist(observed, catalog @ R.T + t)
    rows, cols = linear_sum_assignment(dist)
    d = dist[rows, cols]
    ok = d <= tol[rows]
    pairs = np.column_stack((rows[ok], cols[ok])).astype(np.int64)
    return pairs, float(np.sum(d[ok] * d[ok] * w[rows[ok]]))


def triplet_search(problem, obs_triplets, rule, best):
    """Try the observed triplets ``obs_triplets`` (T, 3) in order, continuing a search
    whose state is ``best`` (a ``records.TripletBest``: pairs (k, 2), n_inliers, cost,
    tried). problem : a ``records.TripletProblem`` (observed, catalog, weights w (n,),
    inlier tolerances tol_mm (n,), the side tolerance alpha_mm, cat_tri and cat_sides
    from ``catalog_triplets``); rule : a ``records.TripletRule``.

    Before each observed triplet: with ``rule.use_confidence``, stop once ``tried``
    reaches ``trials_needed(n_inliers, n, rule.confidence)``. For each ordered catalog
    triplet whose three sides are each within ``alpha_mm`` of the observed triplet's:
    the pose of its three pairs (``absolute_orientation``, weights w), dropped with
    ``rule.constrain`` unless ``stages.pose.reference.pose.facing_cosine`` (the target's
    normal against the direction to the camera) at ``rule.centroid`` is at least
    ``rule.cos_min``; its ``hypothesis_inliers``. The best hypothesis has the most
    inliers (at least ``rule.min_matches``), then the smallest cost. Returns the search's
    state after these triplets (a ``TripletBest``) and whether the confidence rule ended
    the search."""
    observed, catalog = np.asarray(problem.observed, float), np.asarray(problem.catalog, float)
    w, tol = np.asarray(problem.weights, float), np.asarray(problem.tol_mm, float)
    pairs, n_inliers, cost, tried = best
    for a, b, c in np.asarray(obs_triplets, np.int64).reshape(-1, 3):
        if rule.use_confidence and tried >= trials_needed(
            n_inliers, len(observed), rule.confidence
        ):
            return TripletBest(pairs=pairs, n_inliers=n_inliers, cost=cost, tried=tried), True
        tried += 1
        sides = triangle_sides(observed, a, b, c)
        near = np.all(np.abs(problem.cat_sides - sides) <= problem.alpha_mm, axis=1)
        for p in np.flatnonzero(near):
            R, t = absolute_orientation(
                catalog[problem.cat_tri[p]], observed[[a, b, c]], w[[a, b, c]]
            )
            if rule.constrain and not facing_cosine(R, t, rule.centroid) >= rule.cos_min:
                continue
            found, found_cost = hypothesis_inliers(observed, catalog, R, t, w, tol)
            n = len(found)
            if n >= rule.min_matches and (n > n_inliers or (n == n_inliers and found_cost < cost)):
                pairs, n_inliers, cost = found, n, found_cost
    return TripletBest(pairs=pairs, n_inliers=n_inliers, cost=cost, tried=tried), False
