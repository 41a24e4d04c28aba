"""The blob criteria of §3.2 over every candidate component in one call.

Per component (in the order given): the size window, criterion 2 (nLoG, Eqs. 11-14,
17-18) on its active pixels, the moment centroid (Eq. 19) and shape of what the nLoG
keeps, and the penalty score q (§3.4). The arithmetic is that of the reference
functions in ``tofpose.extraction`` (``size_gate``, ``nlog_gate``, ``shape_gate``,
``penalty_score``), which stay the readable specification and are tested against this.
"""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit
from tofpose.kernels.components import (
    component_median_ranges,
    component_table,
    run_labels,
    weighted_moments,
)

#: outcome codes of ``gate_components``
ACCEPTED, OVERSIZE, SIZE, NLOG, SHAPE, PENALTY = 0, 1, 2, 3, 4, 5
#: fewest pixels for which a blob's eccentricity means anything (extraction.SHAPE_MIN_PIXELS)
SHAPE_MIN_PIXELS = 6


@jit
def gaussian_kernel_1d(sigma_px):
    """OpenCV's ``getGaussianKernel(2 ceil(3 sigma) + 1, sigma, CV_32F)``: (k,) float32."""
    n = 2 * int(np.ceil(3.0 * sigma_px)) + 1
    scale = -0.5 / (sigma_px * sigma_px)
    t = np.empty(n)
    s = 0.0
    for i in range(n):
        x = i - (n - 1) * 0.5
        t[i] = np.exp(scale * x * x)
        s += t[i]
    inv = 1.0 / s
    out = np.empty(n, np.float32)
    for i in range(n):
        out[i] = np.float32(t[i] * inv)
    return out


@jit
def _band(k, n):
    """(n, n) float32 matrix whose row i holds the kernel k (odd length, centred) at
    column i, truncated at the edges: multiplying by it filters with zero borders."""
    r = k.shape[0] // 2
    out = np.zeros((n, n), np.float32)
    for i in range(n):
        lo, hi = max(i - r, 0), min(i + r + 1, n)
        out[i, lo:hi] = k[lo - i + r : hi - i + r]
    return out


@jit
def nlog_patch(patch, sigma_px, normalise):
    """-(Laplacian of the Gaussian-smoothed patch), zero outside it (Eqs. 11-14): the
    separable Gaussian then the 4-neighbour Laplacian, as ``extraction.nlog_response``
    does with OpenCV. patch (h, w) float32; returns (h, w) float32."""
    k = gaussian_kernel_1d(sigma_px)
    h, w = patch.shape
    # The separable Gaussian with zero borders as two matrix products (BLAS):
    # smooth = G_h @ patch @ G_w^T, G_n the (n, n) band matrix of the kernel's taps.
    # (a blob's patch is mostly square: then one band serves both sides)
    band_h = _band(k, h)
    band_w = band_h if w == h else _band(k, w)
    smooth = np.dot(band_h, np.dot(patch, band_w.T))
    scale = np.float32(sigma_px * sigma_px) if normalise else np.float32(1.0)
    out = np.empty((h, w), np.float32)
    for y in range(h):
        for x in range(w):
            c = smooth[y, x]
            lap = -4 * c
            if y > 0:
                lap += smooth[y - 1, x]
            if y < h - 1:
                lap += smooth[y + 1, x]
            if x > 0:
                lap += smooth[y, x - 1]
            if x < w - 1:
                lap += smooth[y, x + 1]
            out[y, x] = -lap * scale
    return out


@jit
def gate_components(gray, runs, run_order, run_starts, bbox, area, peak, rho, which, fx,
                    diameters_mm, params):  # fmt: skip
    """Run the §3.2 gates on the listed components (already past the border and dim
    gates).

    gray : (H, W) float32; runs (R, 3) : the active set's runs; run_order, run_starts,
    bbox (K, 4), area (K,), peak (K,), rho (K,) per label from
    ``components.component_table`` (component k's runs, raster order, are
    ``runs[run_order[run_starts[k]:run_starts[k + 1]]]``; rho: median range, mm);
    which : (n,) labels to test; diameters_mm : (N,) catalog diameters; params : (13,)
    float64: h_min_px (<0: range-adaptive window), h_max_px (<0: none), cos(max tilt),
    size_tolerance, size_margin_px, nlog_sigma_px (<=0: matched to each blob's size),
    J_peak and J_t (fractions of the blob's contrast, or absolute with a fixed sigma),
    background, eccentricity limit, I_peak, I_t, q_max.

    Returns status (n,) int64 (``ACCEPTED`` ... ``PENALTY``), size (n, 4) float64 as
    (equivalent diameter, window low, window high, inside the window), moments (n, 4)
    float64 as (u, v, eccentricity, penalty q) and keep_starts (n + 1,), keep_flat: the
    flat indices of the pixels the nLoG keeps (Eq. 18), raster order.
    """
    h_img, w_img = gray.shape
    h_min, h_max, cos_t, size_tol, size_margin = (
        params[0],
        params[1],
        params[2],
        params[3],
        params[4],
    )
    sigma_abs, j_peak_p, j_t_p, background = params[5], params[6], params[7], params[8]
    ecc_max, i_peak, i_t, q_max = params[9], params[10], params[11], params[12]
    n = which.shape[0]
    status = np.empty(n, np.int64)
    size = np.zeros((n, 4))
    moments = np.zeros((n, 4))
    keep_starts = np.zeros(n + 1, np.int64)
    keep_flat = np.empty(0, np.int64)
    d_min_cat, d_max_cat = diameters_mm.min(), diameters_mm.max()
    pieces = []
    for j in range(n):
        k = which[j]
        x, y, bw, bh = bbox[k, 0], bbox[k, 1], bbox[k, 2], bbox[k, 3]
        a = area[k]
        extent = max(bw, bh)
        d_eq = 2.0 * np.sqrt(a / np.pi)
        # size window (extraction.size_gate)
        if h_min >= 0:
            hi_a = h_max if h_max >= 0 else np.inf
            d_lo = 2.0 * np.sqrt(h_min / np.pi)
            d_hi = 2.0 * np.sqrt(hi_a / np.pi)
            size_ok = h_min <= a <= hi_a
            too_big = a > hi_a
        else:
            r = rho[k]
            if not np.isfinite(r) or r <= 0:
                d_lo, d_hi = 0.0, np.inf
            else:
                d_lo = (fx * d_min_cat / r) * np.sqrt(cos_t) / size_tol - size_margin
                d_hi = (fx * d_max_cat / r) * size_tol + size_margin
                d_lo = max(d_lo, 1.0)
            too_big = d_eq > d_hi or extent > d_hi + 1
            size_ok = d_lo <= d_eq <= d_hi and extent <= d_hi + 1 and extent >= d_lo
        size[j, 0], size[j, 1], size[j, 2] = d_eq, d_lo, d_hi
        size[j, 3] = 1.0 if size_ok else 0.0
        if too_big:
            status[j] = OVERSIZE
            pieces.append(np.empty(0, np.int64))
            continue
        if not size_ok:
            status[j] = SIZE
            pieces.append(np.empty(0, np.int64))
            continue
        # criterion 2 (extraction.nlog_gate)
        y0, y1 = max(y - 2, 0), min(y + bh + 2, h_img)
        x0, x1 = max(x - 2, 0), min(x + bw + 2, w_img)
        # the component's pixels, run by run (raster order)
        patch = np.zeros((y1 - y0, x1 - x0), np.float32)
        first_run, end_run = run_starts[k], run_starts[k + 1]
        for q in run_order[first_run:end_run]:
            yy, c0, c1 = runs[q, 0], runs[q, 1], runs[q, 2]
            patch[yy - y0, c0 - x0 : c1 - x0] = gray[yy, c0:c1]
        if sigma_abs > 0:
            jr = nlog_patch(patch, sigma_abs, False)
            j_peak, j_t = j_peak_p, j_t_p
        else:
            sigma = max(0.5, np.sqrt(a / np.pi) / np.sqrt(2.0))
            jr = nlog_patch(patch, sigma, True)
            contrast = peak[k] - background
            j_peak, j_t = j_peak_p * contrast, j_t_p * contrast
        j_t = np.float32(j_t)  # NumPy compares the float32 response in float32
        j_max = -np.inf
        n_keep = 0
        for q in run_order[first_run:end_run]:
            j_row = jr[runs[q, 0] - y0]
            for xx in range(runs[q, 1], runs[q, 2]):
                v = j_row[xx - x0]
                j_max = max(j_max, v)
                if v >= j_t:
                    n_keep += 1
        if j_max < j_peak or n_keep == 0:
            status[j] = NLOG
            pieces.append(np.empty(0, np.int64))
            continue
        kept = np.empty(n_keep, np.int64)
        us = np.empty(n_keep)
        vs = np.empty(n_keep)
        wts = np.empty(n_keep)
        i = 0
        for q in run_order[first_run:end_run]:
            yy = runs[q, 0]
            j_row, g_row = jr[yy - y0], gray[yy]
            for xx in range(runs[q, 1], runs[q, 2]):
                if j_row[xx - x0] >= j_t:
                    kept[i] = yy * w_img + xx
                    us[i] = xx
                    vs[i] = yy
                    wts[i] = max(g_row[xx] - np.float32(background), np.float32(1.0))
                    i += 1
        # moment centroid (Eq. 19) and shape
        cu, cv, ecc = weighted_moments(us, vs, wts)
        moments[j, 0], moments[j, 1], moments[j, 2] = cu, cv, ecc
        pieces.append(kept)
        if not (n_keep < SHAPE_MIN_PIXELS or ecc <= ecc_max):
            status[j] = SHAPE
            continue
        # penalty score (extraction.penalty_score)
        d_k = 2.0 * np.sqrt(n_keep / np.pi)
        q_size = 0.0
        r = rho[k]
        if np.isfinite(r) and r > 0 and d_k >= 3.0:
            best = np.inf
            for dc in diameters_mm:
                best = min(best, abs(np.log(d_k / (fx * dc / r))))
            q_size = min(max(best / np.log(3.0), 0.0), 1.0)
        q_shape = 0.0
        if n_keep >= SHAPE_MIN_PIXELS:
            q_shape = min(max(ecc / max(ecc_max, 1e-6), 0.0), 1.0) ** 2
        span = max(i_peak - i_t, 1e-6)
        q_int = min(max((i_peak - peak[k]) / span, 0.0), 1.0)
        q = 1.0 - (1.0 - q_size) * (1.0 - q_shape) * (1.0 - q_int)
        moments[j, 3] = q
        status[j] = PENALTY if q > q_max else ACCEPTED
    for j in range(n):
        keep_starts[j + 1] = keep_starts[j] + pieces[j].shape[0]
    keep_flat = np.empty(keep_starts[n], np.int64)
    for j in range(n):
        keep_flat[keep_starts[j] : keep_starts[j + 1]] = pieces[j]
    return status, size, moments, keep_starts, keep_flat


@jit
def label_table_and_gates(runs, gray, distance_flat, fx, diameters_mm, params, min_area_px):
    """The active set's components (``components.run_labels`` of its runs, numbered as
    OpenCV numbers them) and their table (``components.component_table``), the border
    and dim gates, the median range of the components that pass them and can be sized
    (``components.component_median_ranges``), then ``gate_components`` on them: the
    blob criteria of §3.1.2-§3.2 in one call.

    runs (R, 3) : the active set's runs (``levels.threshold_mask``); gray (H, W)
    float32; distance_flat (H * W,) float32 mm; fx, diameters_mm, params : as
    ``gate_components`` (params[10] is I_peak); min_area_px : the smallest component
    listed.

    Returns the table (area, bbox, peak, starts, flat), inner (K,) bool (clear of the
    image border), listed (L,) labels of at least ``max(min_area_px, 1)`` pixels,
    testable (L,) bool (inner and bright enough to test), rho (K,) median ranges (NaN
    where not read), and ``gate_components``' results for ``listed[testable]``."""
    h, w = gray.shape
    labels, n_labels = run_labels(runs)
    area, bbox, peak, starts, flat, run_order, run_starts = component_table(
        runs, labels, n_labels, gray
    )
    inner = np.empty(n_labels, np.bool_)
    bright = np.empty(n_labels, np.bool_)
    for k in range(n_labels):
        inner[k] = (bbox[k, 0] > 0 and bbox[k, 1] > 0 and bbox[k, 0] + bbox[k, 2] < w
                    and bbox[k, 1] + bbox[k, 3] < h)  # fmt: skip
        bright[k] = np.float64(peak[k]) >= params[10]  # I_peak
    ranged = np.flatnonzero(inner & bright & (area >= min_area_px))
    rho = np.full(n_labels, np.nan)
    rho[ranged] = component_median_ranges(flat, starts, distance_flat, ranged)
    listed = np.flatnonzero(area >= max(min_area_px, 1))
    testable = inner[listed] & bright[listed]
    which = listed[testable]
    status, size, moments, keep_starts, keep_flat = gate_components(
        gray, runs, run_order, run_starts, bbox, area, peak, rho, which, fx, diameters_mm,
        params,
    )  # fmt: skip
    return (area, bbox, peak, starts, flat, inner, listed, testable, rho, which, status, size,
            moments, keep_starts, keep_flat)  # fmt: skip
