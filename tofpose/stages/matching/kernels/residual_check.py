"""The rigid residual check that ends §4's matching, compiled (``matching.
rigid_residual_check`` is its interface and documentation)."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.pose.kernels.pose import absolute_orientation


@jit
def prune_pairs(observed, catalog, pairs, weights, tol, min_matches):
    """Drop the pair with the largest residual / tolerance until every residual of the
    weighted rigid fit (Eqs. 40-50) is within its tolerance.

    observed (g, 3), catalog (e, 3) mm; pairs (m, 2) int64 rows (observed k, catalog
    i); weights (g,); tol (g,) mm per observed point. Returns (kept pairs (m', 2),
    rejected (r,) observed indices in the order dropped, ok): ok is False when fewer
    than ``min_matches`` pairs would remain, and then every pair is rejected."""
    m = pairs.shape[0]
    alive = np.ones(m, np.bool_)
    rejected = np.empty(m, np.int64)
    n_rej = 0
    n = m
    while n >= min_matches:
        idx = np.flatnonzero(alive)
        x = np.empty((n, 3))
        y = np.empty((n, 3))
        w = np.empty(n)
        for a in range(n):
            y[a] = observed[pairs[idx[a], 0]]
            x[a] = catalog[pairs[idx[a], 1]]
            w[a] = weights[pairs[idx[a], 0]]
        R, t = absolute_orientation(x, y, w)
        worst, worst_ratio, worst_res = 0, -np.inf, 0.0
        for a in range(n):
            s = 0.0
            for r in range(3):
                p = R[r, 0] * x[a, 0] + R[r, 1] * x[a, 1] + R[r, 2] * x[a, 2] + t[r]
                s += (y[a, r] - p) ** 2
            res = np.sqrt(s)
            ratio = res / tol[pairs[idx[a], 0]]
            if ratio > worst_ratio:  # the first of equal ratios, as argmax
                worst, worst_ratio, worst_res = a, ratio, res
        if worst_res <= tol[pairs[idx[worst], 0]]:
            return pairs[idx], rejected[:n_rej], True
        rejected[n_rej] = pairs[idx[worst], 0]
        n_rej += 1
        alive[idx[worst]] = False
        n -= 1
    for a in range(m):
        if alive[a]:
            rejected[n_rej] = pairs[a, 0]
            n_rej += 1
    return np.empty((0, 2), np.int64), rejected[:n_rej], False
