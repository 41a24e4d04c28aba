"""The blob criteria of §3.2 over every candidate component in one call.

Per component (in the order given): the size window, criterion 2 (nLoG, Eqs. 11-14,
17-18) on its active pixels, the moment centroid (Eq. 19) and shape of what the nLoG
keeps, and the penalty score q (§3.4). The arithmetic is that of the reference
functions in ``tofpose.stages.extraction.reference.extraction`` (``size_gate``, ``nlog_gate``,
``shape_gate``, ``penalty_score``, the chain in ``find_candidates``), the readable
specification this is tested against
(``tests/tofpose/stages/extraction/reference/test_extraction.py``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.extraction.constants import MAX_PSF_SIGMA_PX, SHAPE_MIN_PIXELS, WINDOW_PAD_PX
from tofpose.stages.extraction.kernels.components import (
    ComponentTable,
    component_median_ranges,
    component_table,
    run_labels,
    weighted_moments,
)

#: outcome codes of ``gate_components``
ACCEPTED, OVERSIZE, SIZE, NLOG, SHAPE, PENALTY = 0, 1, 2, 3, 4, 5


class GateOutcome(NamedTuple):
    """The §3.2 gates on n listed components (``gate_components``): ``status`` (n,)
    int64 (``ACCEPTED`` ... ``PENALTY``); ``size`` (n, 4) float64 (equivalent diameter,
    window low, window high, inside the window); ``moments`` (n, 4) float64 (u, v,
    eccentricity, penalty q); ``keep_starts`` (n + 1,) and ``keep_flat``: the flat indices
    of the pixels the nLoG keeps (Eq. 18), raster order."""

    status: np.ndarray
    size: np.ndarray
    moments: np.ndarray
    keep_starts: np.ndarray
    keep_flat: np.ndarray


class GatedComponents(NamedTuple):
    """The active set's components and the blob criteria on them
    (``label_table_and_gates``): the ``table`` (a ``ComponentTable``), ``inner`` (K,) bool
    (clear of the image border), ``listed`` (L,) labels of at least the smallest area,
    ``testable`` (L,) bool (inner and bright enough to test), ``rho`` (K,) median ranges
    mm (NaN where not read), ``which`` = listed[testable], the ``gates`` on them (a
    ``GateOutcome``) and the frame's PSF variance ``blur_var_px2`` (px^2)."""

    table: ComponentTable
    inner: np.ndarray
    listed: np.ndarray
    testable: np.ndarray
    rho: np.ndarray
    which: np.ndarray
    gates: GateOutcome
    blur_var_px2: float


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
    separable Gaussian then the 4-neighbour Laplacian, as ``reference.extraction.nlog_response``
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
def blur_widening_px(d_sharp_px, blur_var_px2, peak_contrast, threshold_contrast):
    """How much wider (px) a disc of ``d_sharp_px`` reads in the active set when seen
    through a Gaussian PSF of variance ``blur_var_px2`` (px^2) than without it. The
    blurred disc is taken as a Gaussian of variance sigma^2 + d^2 / 16 + 1/12 (the PSF's,
    the disc's and the pixel's second moments per axis) with peak ``peak_contrast`` over
    the background, cut at ``threshold_contrast``: its diameter there is
    ``2 sqrt(2 v ln(peak / threshold))``, and the widening is that diameter with the PSF
    minus the same without it (0 without blur or when the peak is not above the
    threshold)."""
    if blur_var_px2 <= 0.0 or peak_contrast <= threshold_contrast or threshold_contrast <= 0:
        return 0.0
    sharp = 0.0625 * d_sharp_px * d_sharp_px + 1.0 / 12.0
    cut = 2.0 * np.log(peak_contrast / threshold_contrast)
    return 2.0 * (np.sqrt(cut * (sharp + blur_var_px2)) - np.sqrt(cut * sharp))


@jit
def window_moments(gray, bbox, which):
    """Flux and second moment of each listed component over its box grown by ``WINDOW_PAD_PX``,
    above the median of that window's border, without a threshold (a threshold cuts a
    blurred blob's tails and hides the blur).

    gray (H, W) float32; bbox (K, 4) (x, y, w, h); which (n,) labels. Returns flux (n,)
    counts (the sum of the positive excess) and m2 (n,) px^2 (the mean of the two axes'
    variances of that excess; NaN without one)."""
    h_img, w_img = gray.shape
    n = which.shape[0]
    flux = np.zeros(n)
    m2 = np.full(n, np.nan)
    for j in range(n):
        k = which[j]
        pad = WINDOW_PAD_PX
        x0, y0 = max(bbox[k, 0] - pad, 0), max(bbox[k, 1] - pad, 0)
        x1 = min(bbox[k, 0] + bbox[k, 2] + pad, w_img)
        y1 = min(bbox[k, 1] + bbox[k, 3] + pad, h_img)
        nb = 2 * (x1 - x0) + 2 * max(y1 - y0 - 2, 0)
        border = np.empty(nb, np.float32)
        i = 0
        for x in range(x0, x1):
            border[i] = gray[y0, x]
            border[i + 1] = gray[y1 - 1, x]
            i += 2
        for y in range(y0 + 1, y1 - 1):
            border[i] = gray[y, x0]
            border[i + 1] = gray[y, x1 - 1]
            i += 2
        level = np.float64(np.median(border))
        sw, su, sv, suu, svv = 0.0, 0.0, 0.0, 0.0, 0.0
        for y in range(y0, y1):
            row = gray[y]
            for x in range(x0, x1):
                wt = np.float64(row[x]) - level
                if wt > 0:
                    sw += wt
                    su += wt * x
                    sv += wt * y
                    suu += wt * x * x
                    svv += wt * y * y
        flux[j] = sw
        if sw > 0:
            cu, cv = su / sw, sv / sw
            m2[j] = 0.5 * ((suu / sw - cu * cu) + (svv / sw - cv * cv))
    return flux, m2


@jit
def psf_variance_px2(m2, rho, use, fx, d_min_mm):
    """The frame's PSF variance (px^2 per axis) from its candidates' window moments:
    the smallest over the used components of m2 - r^2 / 4 - 1/12, r the catalog's
    smallest disc's image radius at the component's range (a disc of radius r has
    r^2 / 4 per axis, a pixel 1/12). The smallest reflectors are the least resolved and
    read it best; a larger disc or two merged ones only read larger, so the smallest
    value is the estimate. 0 when none is used or the moments say less than a sharp
    disc, or when every component reads more than ``MAX_PSF_SIGMA_PX`` (discs larger
    than the catalog's: what they show is their size, not the lens). m2, rho, use (n,)."""
    best = np.inf
    for j in range(m2.shape[0]):
        r = rho[j]
        if use[j] and np.isfinite(m2[j]) and np.isfinite(r) and r > 0:
            r_px = 0.5 * fx * d_min_mm / r
            var = m2[j] - 0.25 * r_px * r_px - 1.0 / 12.0
            if var <= MAX_PSF_SIGMA_PX * MAX_PSF_SIGMA_PX:  # else no reflector of ours
                best = min(best, var)
    return max(best, 0.0) if np.isfinite(best) else 0.0


@jit
def blob_brightness(peak, flux, m2, rho, blur_var_px2, fx, d_min_mm, background):
    """The level criterion 1 (Eq. 16) credits each component with, (n,) counts: the
    larger of its peak and ``background`` + its surface brightness, flux / A, with A
    the image area of the disc that its window moments leave once the PSF is taken
    out (pi r^2, r^2 = 4 (m2 - sigma^2 - 1/12)), and at least the catalog's smallest
    disc face-on at its range. A reflector the lens does not resolve spreads its light:
    its peak falls with the PSF, its surface brightness does not; a dim extended
    patch's surface brightness is its own level. peak, flux, m2, rho (n,)."""
    out = np.empty(peak.shape[0])
    for j in range(peak.shape[0]):
        out[j] = peak[j]
        r = rho[j]
        if np.isfinite(r) and r > 0 and np.isfinite(m2[j]):
            a_min = 0.25 * np.pi * (fx * d_min_mm / r) ** 2
            a_disc = max(a_min, 4.0 * np.pi * (m2[j] - blur_var_px2 - 1.0 / 12.0))
            out[j] = max(out[j], background + flux[j] / a_disc)
    return out


@jit
def gate_components(
    gray, runs, table, rho, which, brightness, blur_var_px2, fx, diameters_mm, params
):
    """Run the §3.2 gates on the listed components (already past the border and dim
    gates).

    gray : (H, W) float32; runs (R, 3) : the active set's runs; table : their
    ``components.component_table`` (a ``ComponentTable``: component k's runs, raster
    order, are ``runs[run_order[run_starts[k]:run_starts[k + 1]]]``); rho (K,) : median
    ranges, mm; which : (n,) labels to test; brightness (K,) the level criterion 1
    credits each component with (``blob_brightness``: its peak, or what its flux is worth
    for an unresolved reflector); blur_var_px2 : the frame's PSF variance
    (``psf_variance_px2``; 0 for none), which widens the window's upper end
    (``blur_widening_px``); diameters_mm : (N,) catalog diameters; params : a
    ``records.GateSettings`` (the size window, tilt, nLoG, shape, intensity and penalty
    settings, by name).

    Returns the ``GateOutcome`` of the listed components.
    """
    h_img, w_img = gray.shape
    area, bbox, peak = table.area, table.bbox, table.peak
    run_order, run_starts = table.run_order, table.run_starts
    h_min, h_max, cos_t = params.h_min_px, params.h_max_px, params.cos_max_tilt
    size_tol, size_margin = params.size_tolerance, params.size_margin_px
    sigma_abs, j_peak_p, j_t_p = params.nlog_sigma_px, params.j_peak, params.j_t
    background, ecc_max = params.background, params.eccentricity_max
    i_peak, i_t, q_max = params.i_peak, params.i_t, params.q_max
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
        # size window (reference.extraction.size_gate)
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
                # the margin covers blur up to its size; a wider PSF widens the window
                d_hi = (fx * d_max_cat / r) * size_tol + max(
                    size_margin,
                    blur_widening_px(
                        fx * d_max_cat / r * size_tol,
                        blur_var_px2,
                        peak[k] - background,
                        i_t - background,
                    ),
                )
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
        # criterion 2 (reference.extraction.nlog_gate)
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
        # penalty score (reference.extraction.penalty_score)
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
        q_int = min(max((i_peak - brightness[k]) / span, 0.0), 1.0)
        q = 1.0 - (1.0 - q_size) * (1.0 - q_shape) * (1.0 - q_int)
        moments[j, 3] = q
        status[j] = PENALTY if q > q_max else ACCEPTED
    for j in range(n):
        keep_starts[j + 1] = keep_starts[j] + pieces[j].shape[0]
    keep_flat = np.empty(keep_starts[n], np.int64)
    for j in range(n):
        keep_flat[keep_starts[j] : keep_starts[j + 1]] = pieces[j]
    return GateOutcome(
        status=status, size=size, moments=moments, keep_starts=keep_starts, keep_flat=keep_flat
    )


@jit
def label_table_and_gates(runs, gray, distance_flat, fx, diameters_mm, params, min_area_px):
    """The active set's components (``components.run_labels`` of its runs, numbered as
    OpenCV numbers them) and their table (``components.component_table``), the border
    and dim gates, the median range of the components that pass them and can be sized
    (``components.component_median_ranges``), then ``gate_components`` on them: the
    blob criteria of §3.1.2-§3.2 in one call.

    runs (R, 3) : the active set's runs (``levels.threshold_mask``); gray (H, W)
    float32; distance_flat (H * W,) float32 mm; fx, diameters_mm, params : as
    ``gate_components`` (``params.i_peak`` is I_peak); min_area_px : the smallest component
    listed.

    Returns the ``GatedComponents``: the table, which components are inner (clear of
    the image border), listed (of at least ``max(min_area_px, 1)`` pixels) and testable
    (inner and bright enough), their median ranges (NaN where not read), and
    ``gate_components``' outcome for ``listed[testable]``."""
    h, w = gray.shape
    labels, n_labels = run_labels(runs)
    table = component_table(runs, labels, n_labels, gray)
    area, bbox, peak, starts, flat = table.area, table.bbox, table.peak, table.starts, table.flat
    inner = np.empty(n_labels, np.bool_)
    for k in range(n_labels):
        inner[k] = (
            bbox[k, 0] > 0
            and bbox[k, 1] > 0
            and bbox[k, 0] + bbox[k, 2] < w
            and bbox[k, 1] + bbox[k, 3] < h
        )
    brightness = peak.astype(np.float64)
    rho = np.full(n_labels, np.nan)
    blur_var = 0.0
    d_min = diameters_mm.min()
    if params.h_min_px < 0:  # range-adaptive window: criterion 1 also on surface brightness
        ranged = np.flatnonzero(inner & (area >= max(min_area_px, 1)))
        rho[ranged] = component_median_ranges(flat, starts, distance_flat, ranged)
        flux, m2 = window_moments(gray, bbox, ranged)
        # the PSF from the components bright by their peak, then every component's
        # surface brightness with it, then the PSF again with all that are bright
        blur_var = psf_variance_px2(m2, rho[ranged], brightness[ranged] >= params.i_peak, fx, d_min)
        brightness[ranged] = blob_brightness(
            brightness[ranged], flux, m2, rho[ranged], blur_var, fx, d_min, params.background
        )
        blur_var = psf_variance_px2(m2, rho[ranged], brightness[ranged] >= params.i_peak, fx, d_min)
    bright = brightness >= params.i_peak
    if params.h_min_px >= 0:  # the paper's fixed window: its peak criterion as written
        ranged = np.flatnonzero(inner & bright & (area >= min_area_px))
        rho[ranged] = component_median_ranges(flat, starts, distance_flat, ranged)
    listed = np.flatnonzero(area >= max(min_area_px, 1))
    testable = inner[listed] & bright[listed]
    which = listed[testable]
    gates = gate_components(
        gray, runs, table, rho, which, brightness, blur_var, fx, diameters_mm, params
    )
    return GatedComponents(
        table=table,
        inner=inner,
        listed=listed,
        testable=testable,
        rho=rho,
        which=which,
        gates=gates,
        blur_var_px2=blur_var,
    )
