"""The per-reflector measurement sigmas and Eq. 21's weights, as stated (the model is
ours: the paper weights each reflector by its quality but gives no noise model;
docs/algorithm.md, "Measurement sigmas").

Shapes: gray (H, W) counts; distance (H, W) mm (NaN: no range); a blob is its member
pixels as flat indices (P,) and its centroid (2,) px (u, v). ``constants`` are the
model's constants and floors (a ``core.records.SigmaConstants``, read by field name:
``centroid_sigma_floor_px``, ``range_sigma_floor_mm``, ``single_pixel_sigma_px``,
``split_centroid_px``, ``pool_min_pixels``, ``median_efficiency``,
``uncalibrated_range_sigma_mm``; what ``tofpose.stages.extraction.uncertainty.kernel_constants``
builds).
"""

from __future__ import annotations

import numpy as np

from tofpose.stages.extraction.constants import MAD_TO_SIGMA


def _pixels(shape, pixels):
    rows, cols = np.divmod(np.asarray(pixels, np.int64), shape[1])
    return rows, cols


def shot_noise_centroid_px(gray, pixels, centroid_uv, background) -> float:
    """Shot noise through Eq. 19: sqrt(sum G |p - c|^2) / sum A, G = max(gray, 1) the
    pixel's counts (variance of a Poisson count), A = max(G - bg, 1) its signal."""
    rows, cols = _pixels(gray.shape, pixels)
    g = np.maximum(np.asarray(gray, float).reshape(-1)[pixels], 1.0)
    amp = np.maximum(g - background, 1.0)
    r2 = (cols - centroid_uv[0]) ** 2 + (rows - centroid_uv[1]) ** 2
    return float(np.sqrt((g * r2).sum()) / amp.sum())


def centroid_sigma_px(
    gray, pixels, centroid_uv, background, split: bool, constants, full_scale=np.inf
) -> float:
    """A blob's centroid sigma per image axis, px: shot noise, the floor, the pixel
    grid's sampling error (single_pixel_sigma_px n^-1.5), for a half cut out of a
    merged pair the light misassigned at the cut (split_centroid_px) and, for a blob
    with pixels at or above ``full_scale``, the clipped contour's error
    (``clipped_contour_sigma_px``), in quadrature."""
    n = len(pixels)
    sampling = constants.single_pixel_sigma_px * max(float(n), 1.0) ** -1.5
    neighbour = constants.split_centroid_px if split else 0.0
    shot = shot_noise_centroid_px(gray, pixels, centroid_uv, background)
    floor = constants.centroid_sigma_floor_px
    g = np.asarray(gray).reshape(-1)[np.asarray(pixels)]
    clipped = clipped_contour_sigma_px(n, int(np.count_nonzero(g >= full_scale)))
    return float(np.sqrt(shot**2 + floor**2 + sampling**2 + neighbour**2 + clipped**2))


def clipped_contour_sigma_px(n_pixels: int, n_clipped: int) -> float:
    """Centroid sigma per axis, px, of a blob of ``n_pixels`` with ``n_clipped`` at full
    scale: sqrt(v(q) / (pi r)), v(q) = q^3 / 3 - q^4 / 4, q the rim's clipped share,
    r = sqrt(n / pi); 0 without a clipped pixel (``kernels.sigmas.clipped_contour_sigma_px``)."""
    if n_clipped <= 0:
        return 0.0
    n = max(float(n_pixels), 1.0)
    rim = 2.0 * np.sqrt(np.pi * n)
    q = min(max((rim - (n - n_clipped)) / rim, 0.0), 1.0)
    return float(np.sqrt((q**3 / 3.0 - q**4 / 4.0) / (np.pi * np.sqrt(n / np.pi))))


def range_spread(gray, distance, pixels, background) -> tuple[float, float, int]:
    """A blob's own range spread and the ToF noise model's unit there: (MAD sigma of its
    valid ranges (NaN below 3), mean of sqrt(G) / A over them (NaN with none), how many
    are valid). The model: a pixel's range sigma is k sqrt(G) / A (Lange 2000)."""
    d = np.asarray(distance, np.float32).reshape(-1)[pixels]
    valid = np.isfinite(d)
    g = np.maximum(np.asarray(gray, float).reshape(-1)[pixels][valid], 1.0)
    amp = np.maximum(g - background, 1.0)
    n_valid = int(valid.sum())
    unit = float(np.mean(np.sqrt(g) / amp)) if n_valid else np.nan
    mad = np.nan
    if n_valid >= 3:
        dv = d[valid]
        med = np.float32(np.median(dv.astype(float)))
        mad = MAD_TO_SIGMA * float(np.median(np.abs(dv - med).astype(float)))
    return mad, unit, n_valid


def range_sigmas_mm(gray, distance, blobs_pixels, background, constants) -> np.ndarray:
    """Each blob's range sigma (n,), mm: k (the median over the frame's blobs with at
    least pool_min_pixels valid ranges of their MAD / unit) pools the noise model; a
    blob's per-pixel sigma is the larger of its own MAD and k times its unit, times the
    median's efficiency over sqrt(n_valid), at least the floor;
    uncalibrated_range_sigma_mm when nothing calibrates k and the blob has fewer than 3
    ranges."""
    spreads = [range_spread(gray, distance, p, background) for p in blobs_pixels]
    ratios = [
        mad / unit
        for mad, unit, n in spreads
        if n >= constants.pool_min_pixels and np.isfinite(mad) and unit > 0
    ]
    k = float(np.median(ratios)) if ratios else np.nan
    out = []
    for mad, unit, n in spreads:
        per_pixel = mad if np.isfinite(mad) else 0.0
        if np.isfinite(k):
            per_pixel = max(per_pixel, k * (unit if np.isfinite(unit) else 0.0))
        s = constants.median_efficiency * per_pixel / np.sqrt(max(n, 1))
        if not np.isfinite(k) and n < 3:
            s = constants.uncalibrated_range_sigma_mm
        out.append(max(s, constants.range_sigma_floor_mm))
    return np.array(out)


def weights(range_mm, range_sigma_mm, centroid_sigma_px, fx_px) -> np.ndarray:
    """Eq. 21's weights (n,), 1 / mm^2: the inverse variance of a measured point, its
    range sigma and its lateral sigma rho sigma_px / fx in quadrature."""
    lateral = np.asarray(range_mm, float) * np.asarray(centroid_sigma_px, float) / fx_px
    return 1.0 / (np.asarray(range_sigma_mm, float) ** 2 + lateral**2)
