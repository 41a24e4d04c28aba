"""The two-centre split of a merged pair's pixels (``confirmation.split_in_two``), compiled:
intensity-weighted 2-means by Lloyd's iteration from the ends of the component's major
axis. In NumPy the dozen small array operations per iteration cost ~0.5 ms a frame
whenever markers 7 and 8 merge (5-7 m), more than the rest of the acquisition pass."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.ellipses.constants import MIN_ELONGATION

#: ``two_centre_split`` status: split done; not elongated as two discs side by side are;
#: every pixel nearer one centre
SPLIT_OK, SPLIT_ROUND, SPLIT_ONE_SIDED = 0, 1, 2


@jit
def two_centre_split(cols, rows, weight, iterations):
    """Split pixels (u = cols, v = rows; (n,) float64) weighted by ``weight`` (n,) (> 0 in
    sum) in two: the weighted mean and covariance give the major axis; the centres start
    at the mean plus half the extreme projections on it and move ``iterations`` times to
    the weighted mean of the pixels nearer each (ties to the first). Returns (near (n,)
    int64 0/1, centres (2, 2) rows (u, v), status ``SPLIT_*``)."""
    n = cols.shape[0]
    near = np.zeros(n, np.int64)
    centres = np.zeros((2, 2))
    sw, mu, mv = 0.0, 0.0, 0.0
    for i in range(n):
        sw += weight[i]
        mu += weight[i] * cols[i]
        mv += weight[i] * rows[i]
    mu /= sw
    mv /= sw
    cuu, cvv, cuv = 0.0, 0.0, 0.0
    for i in range(n):
        du, dv = cols[i] - mu, rows[i] - mv
        cuu += weight[i] * du * du
        cvv += weight[i] * dv * dv
        cuv += weight[i] * du * dv
    cuu /= sw
    cvv /= sw
    cuv /= sw
    half_trace = 0.5 * (cuu + cvv)
    root = np.sqrt(max(half_trace * half_trace - (cuu * cvv - cuv * cuv), 0.0))
    major, minor = half_trace + root, half_trace - root
    if minor <= 0 or major < MIN_ELONGATION**2 * minor:
        return near, centres, SPLIT_ROUND
    if cuv != 0.0:
        au, av = major - cvv, cuv
    elif cuu >= cvv:
        au, av = 1.0, 0.0
    else:
        au, av = 0.0, 1.0
    norm = np.sqrt(au * au + av * av)
    au /= norm
    av /= norm
    lo, hi = np.inf, -np.inf
    for i in range(n):
        a = (cols[i] - mu) * au + (rows[i] - mv) * av
        lo = min(lo, a)
        hi = max(hi, a)
    centres[0, 0], centres[0, 1] = mu + 0.5 * lo * au, mv + 0.5 * lo * av
    centres[1, 0], centres[1, 1] = mu + 0.5 * hi * au, mv + 0.5 * hi * av
    for _ in range(iterations):
        n1 = 0
        for i in range(n):
            d0 = (cols[i] - centres[0, 0]) ** 2 + (rows[i] - centres[0, 1]) ** 2
            d1 = (cols[i] - centres[1, 0]) ** 2 + (rows[i] - centres[1, 1]) ** 2
            near[i] = 1 if d1 < d0 else 0
            n1 += near[i]
        if n1 == 0 or n1 == n:
            return near, centres, SPLIT_ONE_SIDED
        s = np.zeros((2, 3))
        for i in range(n):
            k = near[i]
            s[k, 0] += weight[i]
            s[k, 1] += weight[i] * cols[i]
            s[k, 2] += weight[i] * rows[i]
        for k in range(2):
            total = max(s[k, 0], 1e-12)
            centres[k, 0] = s[k, 1] / total
            centres[k, 1] = s[k, 2] / total
    return near, centres, SPLIT_OK
