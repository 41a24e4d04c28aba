"""Per-blob pixel statistics behind the measurement sigmas
(``tofpose.stages.extraction.uncertainty``),
all blobs in one call."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.indexing import row_col
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.extraction.constants import MAD_TO_SIGMA


@jit
def blob_pixel_stats(flat, starts, centroids, gray, distance, background):
    """For each blob j (pixels ``flat[starts[j]:starts[j + 1]]``, flat indices):

    shot_px : shot-noise centroid sigma through Eq. 19, sqrt(sum G |p - c|^2) / sum A;
    n_px : pixel count; own_mad_mm : 1.4826 x the median absolute deviation of its valid
    ranges (NaN below 3); model_unit : mean of sqrt(G) / A over valid pixels (NaN with
    none); n_valid : pixels with a range. G = max(gray, 1), A = max(G - bg, 1).

    centroids : (n, 2) px; gray : (H, W) float32 counts; distance : (H, W) float32 mm.
    Returns five (n,) arrays (n_px, n_valid int64).
    """
    w = gray.shape[1]
    n = centroids.shape[0]
    shot = np.empty(n)
    n_px = np.empty(n, np.int64)
    own_mad = np.full(n, np.nan)
    model_unit = np.full(n, np.nan)
    n_valid = np.zeros(n, np.int64)
    gray_f = gray.reshape(-1)
    inv_w = 1.0 / w
    dist_f = distance.reshape(-1)
    for j in range(n):
        a, b = starts[j], starts[j + 1]
        cu, cv = centroids[j, 0], centroids[j, 1]
        s_g_r2 = 0.0
        s_amp = 0.0
        s_unit = 0.0
        d_ok = np.empty(b - a, np.float32)
        m = 0
        for i in range(a, b):
            p = flat[i]
            row, col = row_col(p, w, inv_w)
            g = max(np.float64(gray_f[p]), 1.0)
            amp = max(g - background, 1.0)
            s_g_r2 += g * ((col - cu) ** 2 + (row - cv) ** 2)
            s_amp += amp
            d = dist_f[p]
            if np.isfinite(d):
                d_ok[m] = d
                s_unit += np.sqrt(g) / amp
                m += 1
        shot[j] = np.sqrt(s_g_r2) / s_amp
        n_px[j] = b - a
        n_valid[j] = m
        if m:
            model_unit[j] = s_unit / m
        if m >= 3:
            med = np.float32(median_inplace(d_ok[:m].copy()))
            dev = np.empty(m, np.float32)
            for i in range(m):
                dev[i] = abs(d_ok[i] - med)
            own_mad[j] = MAD_TO_SIGMA * median_inplace(dev)
    return shot, n_px, own_mad, model_unit, n_valid


@jit
def clipped_contour_sigma_px(n_pixels, n_clipped):
    """Centroid sigma per axis, px, of a blob of ``n_pixels`` of which ``n_clipped`` are
    at full scale (``uncertainty`` module docstring): a rim pixel whose coverage c is
    above 1 / k (k the overexposure) reads full scale like the core, an error of 1 - c
    at the lever arm r; the others keep their coverage. Over c uniform in [0, 1] the
    error's variance is v(q) = q^3 / 3 - q^4 / 4 with q = 1 - 1 / k the rim's clipped
    share, here (its ~2 sqrt(pi n) pixels less the n - n_clipped graded ones) over
    them; over the ~2 pi r rim pixels and the area pi r^2, r = sqrt(n / pi), the
    centroid's variance per axis is v(q) / (pi r) (1 / (12 pi r) for a binary image,
    q = 1: 0.13 px at 8 px, 0.07 px at 100). 0 without a clipped pixel."""
    if n_clipped <= 0:
        return 0.0
    n = max(float(n_pixels), 1.0)
    rim = 2.0 * np.sqrt(np.pi * n)
    q = min(max((rim - (n - n_clipped)) / rim, 0.0), 1.0)
    v = q**3 / 3.0 - q**4 / 4.0
    return np.sqrt(v / (np.pi * np.sqrt(n / np.pi)))


@jit
def blob_sigmas(flat, starts, centroids, gray, distance, background, split, full_scale, sigmas):
    """Centroid sigma (n,) px and range sigma (n,) mm of each blob: the model of
    ``uncertainty.measurement_sigmas`` (its docstring) on ``blob_pixel_stats``, in one
    call. split : (n,) bool, blob cut out of a merged component; full_scale : the gray
    at which a pixel is clipped (``clipped_contour_sigma_px`` of each blob's);
    sigmas : that module's constants and the floors (a ``core.records.SigmaConstants``,
    ``uncertainty.kernel_constants``)."""
    shot, n_px, own_mad, unit, n_valid = blob_pixel_stats(
        flat, starts, centroids, gray, distance, background
    )
    n = shot.shape[0]
    sigma_px = np.empty(n)
    gray_f = gray.reshape(-1)
    for j in range(n):
        sampling = sigmas.single_pixel_sigma_px * max(float(n_px[j]), 1.0) ** -1.5
        neighbour = sigmas.split_centroid_px if split[j] else 0.0
        floor = sigmas.centroid_sigma_floor_px
        n_clipped = 0
        for i in range(starts[j], starts[j + 1]):
            if gray_f[flat[i]] >= full_scale:
                n_clipped += 1
        clipped = clipped_contour_sigma_px(n_px[j], n_clipped)
        sigma_px[j] = np.sqrt(shot[j] ** 2 + floor**2 + sampling**2 + neighbour**2 + clipped**2)
    ratios = np.empty(n)
    m = 0
    for j in range(n):
        if n_valid[j] >= sigmas.pool_min_pixels and np.isfinite(own_mad[j]) and unit[j] > 0:
            ratios[m] = own_mad[j] / unit[j]
            m += 1
    k = median_inplace(ratios[:m]) if m else np.nan
    sigma_range = np.empty(n)
    for j in range(n):
        per_pixel = own_mad[j] if np.isfinite(own_mad[j]) else 0.0
        if np.isfinite(k):
            per_pixel = max(per_pixel, k * (unit[j] if np.isfinite(unit[j]) else 0.0))
        s = sigmas.median_efficiency * per_pixel / np.sqrt(max(n_valid[j], 1))
        if not np.isfinite(k) and n_valid[j] < 3:
            s = sigmas.uncalibrated_range_sigma_mm
        sigma_range[j] = max(s, sigmas.range_sigma_floor_mm)
    return sigma_px, sigma_range
