"""Connected components of the active pixel set, tabulated in one pass (§3.1.2-§3.2).

OpenCV labels the active set (``cv2.connectedComponents``, over the set's bounding box);
its ``...WithStats`` variant also tabulates the background and costs ~7x more. These
kernels take the labels and give what the blob criteria read: each component's area,
bounding box, brightest pixel, its member pixels (flat indices, raster order) and the
median of its valid ranges.
"""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit
from tofpose.kernels.stats import median_inplace


@jit
def component_table(labels, n_labels, gray, x_origin, y_origin, runs):
    """Per component k = 0 .. n_labels - 1 (0, the background, is left empty).

    labels : (h, w) int32 from ``cv2.connectedComponents`` over the part of the image
    whose top-left pixel is (``x_origin``, ``y_origin``) (the active set's bounding box:
    labelling the whole frame for a few lit pixels cost most of the time); gray :
    (H, W) float32, the whole frame; runs : (R, 3) int64, the labelled set's horizontal
    runs in raster order (``levels.threshold_mask``), in whole-frame coordinates. A run
    lies in one component (its pixels are neighbours), so the table is built run by run:
    at 0.7 m ~200 runs instead of the ~64,000 pixels of the box, twice (9x faster).
    Returns, in whole-frame coordinates, area (K,) int64, bbox (K, 4) int64 as
    (x, y, w, h), peak (K,) float32 counts, starts (K + 1,) int64 and flat (P,) int64:
    the flat indices (row * W + col) of component k's pixels, in raster order, are
    ``flat[starts[k]:starts[k + 1]]``.
    """
    h, w = labels.shape
    w_img = gray.shape[1]
    area = np.zeros(n_labels, np.int64)
    x0 = np.full(n_labels, w + x_origin, np.int64)  # (the background's box: as OpenCV's)
    y0 = np.full(n_labels, h + y_origin, np.int64)
    x1 = np.full(n_labels, x_origin - 1, np.int64)
    y1 = np.full(n_labels, y_origin - 1, np.int64)
    peak = np.full(n_labels, -np.inf, np.float32)
    n_runs = runs.shape[0]
    run_label = np.empty(n_runs, np.int64)
    for i in range(n_runs):
        r, first, end = runs[i, 0], runs[i, 1], runs[i, 2]
        k = labels[r - y_origin, first - x_origin]
        run_label[i] = k
        area[k] += end - first
        x0[k] = min(x0[k], first)
        x1[k] = max(x1[k], end - 1)
        y0[k] = min(y0[k], r)
        y1[k] = max(y1[k], r)
        row = gray[r]
        top = peak[k]
        for c in range(first, end):
            top = max(top, row[c])
        peak[k] = top
    starts = np.zeros(n_labels + 1, np.int64)
    for k in range(1, n_labels):
        starts[k + 1] = starts[k] + area[k]
    fill = starts[:-1].copy()
    flat = np.empty(starts[n_labels], np.int64)
    for i in range(n_runs):
        k = run_label[i]
        base = runs[i, 0] * w_img
        f = fill[k]
        for c in range(runs[i, 1], runs[i, 2]):
            flat[f] = base + c
            f += 1
        fill[k] = f
    bbox = np.empty((n_labels, 4), np.int64)
    for k in range(n_labels):
        bbox[k, 0] = x0[k]
        bbox[k, 1] = y0[k]
        bbox[k, 2] = x1[k] - x0[k] + 1
        bbox[k, 3] = y1[k] - y0[k] + 1
    return area, bbox, peak, starts, flat


@jit
def median_of_finite(values):
    """``np.median`` of the finite entries of a 1-D float32 array (NaN when none), with
    NumPy's arithmetic: the two middle values of an even count averaged in float32."""
    buf = np.empty(values.shape[0], values.dtype)
    n = 0
    for i in range(values.shape[0]):
        v = values[i]
        if np.isfinite(v):
            buf[n] = v
            n += 1
    if n == 0:
        return np.nan
    return median_inplace(buf[:n])


@jit
def component_median_ranges(flat, starts, distance_flat, which):
    """Median range (mm) of each listed component's valid pixels (NaN when it has none).

    flat, starts : from ``component_table``; distance_flat : (H * W,) float32 mm, NaN
    where invalid; which : (n,) int64 component labels. Returns (n,) float64.
    """
    out = np.empty(which.shape[0])
    for j in range(which.shape[0]):
        k = which[j]
        idx = flat[starts[k] : starts[k + 1]]
        out[j] = median_of_finite(distance_flat[idx])
    return out


@jit
def weighted_moments(us, vs, w):
    """Weighted centroid (Eq. 19) and eccentricity from the second moments of a point
    set: us, vs, w (n,) float64. Returns (u, v, eccentricity)."""
    sw = 0.0
    su = 0.0
    sv = 0.0
    for i in range(us.shape[0]):
        sw += w[i]
        su += us[i] * w[i]
        sv += vs[i] * w[i]
    cu, cv = su / sw, sv / sw
    cuu = 0.0
    cvv = 0.0
    cuv = 0.0
    for i in range(us.shape[0]):
        du, dv = us[i] - cu, vs[i] - cv
        cuu += w[i] * du * du
        cvv += w[i] * dv * dv
        cuv += w[i] * du * dv
    cuu, cvv, cuv = cuu / sw, cvv / sw, cuv / sw
    tr, det = cuu + cvv, cuu * cvv - cuv * cuv
    disc = np.sqrt(max(tr * tr / 4 - det, 0.0))
    l1, l2 = tr / 2 + disc, tr / 2 - disc
    ecc = np.sqrt(max(0.0, 1.0 - l2 / l1)) if l1 > 1e-12 else 0.0
    return cu, cv, ecc
