"""Triplet hypotheses (``matching.match_by_triplets``) as a kernel: for each observed
triplet, every catalog triplet with the same side lengths, its rigid pose, the facing
constraint, and the inliers of the one-to-one assignment of every observed point to the
predicted reflectors. Our fallback after annealing and the RANSAC comparison of
``bench/robustness.py`` both run it; in NumPy an observed triplet cost ~22 us of calls
(~0.5 us here), which made RANSAC at an equal time budget a comparison of call
overheads."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.matching.kernels.assignment import linear_sum_assignment
from tofpose.stages.matching.records import TripletBest
from tofpose.stages.pose.kernels.pose import absolute_orientation, facing_cosine


@jit
def trials_needed(n_inliers, n_observed, confidence):
    """Observed triplets to draw (without repetition) so that, with ``n_inliers`` of
    ``n_observed`` blobs being markers, at least one all-marker triplet was drawn with
    probability ``confidence``: ``log(1 - p) / log(1 - C(I, 3) / C(n, 3))`` (the standard
    RANSAC count, Fischler and Bolles 1981, with the all-inlier probability of a triplet
    drawn without replacement). Infinite while fewer than 3 inliers are known."""
    if n_inliers < 3 or n_observed < 3:
        return np.inf
    good = n_inliers * (n_inliers - 1) * (n_inliers - 2) // 6
    every = n_observed * (n_observed - 1) * (n_observed - 2) // 6
    p_good = good / every
    if p_good >= 1.0:
        return 1.0
    return np.log(1.0 - confidence) / np.log(1.0 - p_good)


@jit
def _distance(a, b):
    """|a - b| of two 3-vectors, the squares summed in order."""
    d0, d1, d2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@jit
def _numpy_sum(v, n):
    """``float(np.sum(v[:n]))`` with NumPy's summation order (eight partial sums from
    eight values on; these sums hold at most a catalog's worth of values)."""
    if n < 8:
        s = 0.0
        for i in range(n):
            s += v[i]
        return s
    r = v[:8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += v[i + j]
        i += 8
    s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        s += v[i]
        i += 1
    return s


@jit
def catalog_triplets(catalog):
    """Every ordered triplet (i, j, k) of distinct reflectors, in
    ``itertools.permutations`` order, (P, 3) int64, and its side lengths (ij, jk, ik),
    (P, 3) mm."""
    e = catalog.shape[0]
    n = e * (e - 1) * (e - 2)
    tri = np.empty((max(n, 0), 3), np.int64)
    sides = np.empty((max(n, 0), 3))
    p = 0
    for i in range(e):
        for j in range(e):
            for k in range(e):
                if i != j and j != k and i != k:
                    tri[p, 0], tri[p, 1], tri[p, 2] = i, j, k
                    sides[p, 0] = _distance(catalog[i], catalog[j])
                    sides[p, 1] = _distance(catalog[j], catalog[k])
                    sides[p, 2] = _distance(catalog[i], catalog[k])
                    p += 1
    return tri, sides


@jit
def triplet_search(problem, obs_triplets, rule, best):
    """Try the observed triplets ``obs_triplets`` (T, 3) in order, continuing a search
    whose state is ``best`` (a ``records.TripletBest``: the best hypothesis so far as
    (observed, catalog) pairs, its inliers and weighted squared residual, the triplets
    tried).

    problem : a ``records.TripletProblem`` (the observed and catalog points, weights,
    inlier tolerances, side tolerance, ``catalog_triplets``); rule : a
    ``records.TripletRule`` (the facing constraint, ``min_matches``, the confidence
    rule: stop once the triplets tried reach ``trials_needed`` for the best inlier
    count).

    A hypothesis: the rigid pose of the triplet's three pairs (``absolute_orientation``);
    each observed point is assigned one-to-one to the predicted reflectors (least total
    distance), and the pairs within their tolerance are its inliers. The best has the
    most inliers (at least ``min_matches``), then the smallest sum of w d^2. Returns the
    search's state after these triplets (a ``TripletBest``) and whether the confidence
    rule ended the search."""
    observed, catalog, w, tol = problem.observed, problem.catalog, problem.weights, problem.tol_mm
    cat_tri, cat_sides, alpha = problem.cat_tri, problem.cat_sides, problem.alpha_mm
    pairs, best_n, best_cost, tried = best.pairs, best.n_inliers, best.cost, best.tried
    n_obs, e = observed.shape[0], catalog.shape[0]
    pred = np.empty((e, 3))
    dist = np.empty((n_obs, e))
    x3 = np.empty((3, 3))
    y3 = np.empty((3, 3))
    w3 = np.empty(3)
    terms = np.empty(min(n_obs, e))
    for q in range(obs_triplets.shape[0]):
        if rule.use_confidence and tried >= trials_needed(best_n, n_obs, rule.confidence):
            return TripletBest(pairs=pairs, n_inliers=best_n, cost=best_cost, tried=tried), True
        tried += 1
        a, b, c = obs_triplets[q, 0], obs_triplets[q, 1], obs_triplets[q, 2]
        o0 = _distance(observed[a], observed[b])
        o1 = _distance(observed[b], observed[c])
        o2 = _distance(observed[a], observed[c])
        for p in range(cat_tri.shape[0]):
            if not (
                abs(cat_sides[p, 0] - o0) <= alpha
                and abs(cat_sides[p, 1] - o1) <= alpha
                and abs(cat_sides[p, 2] - o2) <= alpha
            ):
                continue
            for r in range(3):
                x3[r] = catalog[cat_tri[p, r]]
                y3[r] = observed[obs_triplets[q, r]]
                w3[r] = w[obs_triplets[q, r]]
            R, t = absolute_orientation(x3, y3, w3)
            if rule.constrain and not facing_cosine(R, t, rule.centroid) >= rule.cos_min:
                continue
            for i in range(e):
                for r in range(3):
                    pred[i, r] = (
                        catalog[i, 0] * R[r, 0]
                        + catalog[i, 1] * R[r, 1]
                        + catalog[i, 2] * R[r, 2]
                        + t[r]
                    )
            for k in range(n_obs):
                for i in range(e):
                    dist[k, i] = _distance(observed[k], pred[i])
            rows, cols = linear_sum_assignment(dist)
            n = 0
            for z in range(rows.shape[0]):
                d = dist[rows[z], cols[z]]
                if d <= tol[rows[z]]:
                    terms[n] = d * d * w[rows[z]]
                    n += 1
            cost = _numpy_sum(terms, n)
            if n >= rule.min_matches and (n > best_n or (n == best_n and cost < best_cost)):
                pairs = np.empty((n, 2), np.int64)
                m = 0
                for z in range(rows.shape[0]):
                    if dist[rows[z], cols[z]] <= tol[rows[z]]:
                        pairs[m, 0], pairs[m, 1] = rows[z], cols[z]
                        m += 1
                best_n, best_cost = n, cost
    return TripletBest(pairs=pairs, n_inliers=best_n, cost=best_cost, tried=tried), False
