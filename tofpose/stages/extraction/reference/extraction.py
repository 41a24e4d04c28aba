"""§3.1-§3.2 as stated: the frame's levels and the active pixel set A with the N_max cap
(§3.1.1), the nLoG response (Eqs. 11-14), the 8-connected components of A and the blob
criteria B1-B4 (Eqs. 15-18) with our range-adaptive size window (the paper's H_min/H_max
area window in its preset), the lens-blur allowance, the shape gate, the moment centroid
and eccentricity (Eq. 19's moments), the penalty score q (§3.4) and the L best.

Shapes: gray (H, W) float32 counts; distance (H, W) float32 mm, NaN where invalid; a
component's pixels are flat indices (n,) (row * W + col) in raster order; a bounding box
is (x, y, w, h) px as OpenCV gives it. The frame is float32, so a level computed in
float64 is rounded to float32 before a pixel is compared with it, and the nLoG response
is float32 (OpenCV's filters). ``find_candidates`` chains the rules as
``tofpose.stages.extraction.extraction.find_candidate_blobs`` does; ``frame_levels`` restates
``tofpose.stages.extraction.extraction.frame_levels``.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.stages.extraction.constants import (
    DARK_PERCENTILE,
    LEVEL_STRIDE,
    MAD_TO_SIGMA,
    MAX_PSF_SIGMA_PX,
    SATURATED_COUNTS,
    SHAPE_MIN_PIXELS,
    WINDOW_PAD_PX,
)

#: the nLoG patch's reach beyond a component's box, px (zeros outside A, §3.1.2)
NLOG_PAD_PX = 2
#: why a component is not a candidate (``tofpose.stages.extraction.extraction.REJECT_REASONS``'
# names)
REJECT_REASONS = ("border", "dim", "size", "oversize", "nlog", "shape", "penalty", "rank")


class FrameLevels(NamedTuple):
    """The frame's levels, counts. ``raw_threshold`` is I_t, ``peak_threshold`` I_peak
    (never below I_t); ``n_active`` the size of A once the N_max cap has applied (0 before
    ``active_pixel_set``)."""

    background: float
    noise_sigma: float
    i_max: float
    raw_threshold: float
    peak_threshold: float
    saturated_fraction: float
    dark_level: float
    n_active: int = 0


class SizeVerdict(NamedTuple):
    """The size window's verdict on one component: its equivalent diameter and the
    window (px), whether it is inside, and whether it is too big for one reflector."""

    diameter_px: float
    window_lo_px: float
    window_hi_px: float
    inside: bool
    too_big: bool


class CandidateBlob(NamedTuple):
    """An accepted blob: pixels (n,) int64 flat indices kept by the nLoG (Eq. 18),
    sorted; area_px = n; bbox of its component; centroid_uv (2,) the moment centroid
    (Eq. 19's weights ``moment_weights``); distance_mm its component's median range;
    peak_counts its component's brightest pixel; eccentricity; penalty q."""

    pixels: np.ndarray
    area_px: int
    bbox: tuple[int, int, int, int]
    centroid_uv: np.ndarray
    distance_mm: float
    peak_counts: float
    eccentricity: float
    penalty: float


class OversizeBlob(NamedTuple):
    """A component too large for one reflector (merged markers, for §3.3): all its pixels
    (n,) int64 flat indices, sorted; area, bbox, brightest pixel, median range."""

    pixels: np.ndarray
    area_px: int
    bbox: tuple[int, int, int, int]
    peak_counts: float
    distance_mm: float


class Rejected(NamedTuple):
    """A component that is not a candidate: its box centre (u, v) px (the centroid for
    "rank"), equivalent diameter px, and the rule that refused it (``REJECT_REASONS``)."""

    u_px: float
    v_px: float
    diameter_px: float
    reason: str


class WrongSize(NamedTuple):
    """A bright component outside the size window: its equivalent diameter, the window,
    and its median range."""

    diameter_px: float
    expected_min_px: float
    expected_max_px: float
    distance_mm: float


class Candidates(NamedTuple):
    """What ``find_candidates`` finds. accepted : at most L blobs, best (lowest q, then
    brightest) first; oversize : in label order; rejected : every listed component that
    is not a candidate, in label order, then the ones beyond L in rank order; wrong_size
    : the tested components outside the size window, in label order; levels : as applied
    (I_t after the N_max cap); psf_sigma_px : the frame's lens blur (0 for the paper's
    window); active_mask : (H, W) bool, A."""

    accepted: tuple[CandidateBlob, ...]
    oversize: tuple[OversizeBlob, ...]
    rejected: tuple[Rejected, ...]
    wrong_size: tuple[WrongSize, ...]
    levels: FrameLevels
    psf_sigma_px: float
    active_mask: np.ndarray


# -- §3.1.1: the frame's levels ------------------------------------------------------------


def level_subsample(gray, *, stride=LEVEL_STRIDE) -> np.ndarray:
    """(n,) float32: every ``stride``-th pixel of every ``stride``-th row of gray (H, W)."""
    return np.asarray(gray, np.float32)[::stride, ::stride].ravel()


def background_and_mad(sub) -> tuple[float, float]:
    """The background (median) and its median absolute deviation of a subsample (n,)
    float32, with NumPy's float32 median (two middle values averaged in float32)."""
    bg = np.median(sub)
    return float(bg), float(np.median(np.abs(sub - bg)))


def noise_sigma(mad, background) -> float:
    """The background's noise sigma: the MAD's normal sigma, at least the shot noise
    sqrt(background) (at least 1)."""
    return max(MAD_TO_SIGMA * mad, float(np.sqrt(max(background, 1.0))))


def dark_level(sub, background, *, percentile=DARK_PERCENTILE) -> float:
    """The gray of pixels without a return: the ``percentile``-th percentile of the
    subsample (n,) by nearest rank (the value of 0-based rank int(n percentile / 100) in
    ascending order), at most the background."""
    k = int(len(sub) * percentile / 100.0)
    return min(float(np.sort(sub)[k]), background)


def raw_threshold(background, i_max, sigma, config: ExtractionConfig) -> float:
    """I_t (§3.1.1): ``raw_threshold_abs`` in the paper preset; ours
    ``bg + raw_threshold_rel (I_max - bg)``, at least ``noise_floor_sigma`` sigmas over bg."""
    if config.raw_threshold_abs is not None:
        return float(config.raw_threshold_abs)
    contrast = i_max - background
    return max(
        background + config.raw_threshold_rel * contrast,
        background + config.noise_floor_sigma * sigma,
    )


def peak_threshold(background, i_max, i_t, config: ExtractionConfig) -> float:
    """I_peak of criterion 1 (Eq. 16): ``peak_abs`` in the paper preset, ours
    ``bg + peak_rel (I_max - bg)``; never below I_t."""
    i_peak = (
        config.peak_abs
        if config.peak_abs is not None
        else background + config.peak_rel * (i_max - background)
    )
    return max(i_peak, i_t)


def saturated_fraction(gray, *, saturated_counts=SATURATED_COUNTS) -> float:
    """The fraction of the frame's pixels (H, W) at or above ``saturated_counts``."""
    g = np.asarray(gray, np.float32)
    return float(np.count_nonzero(g >= np.float32(saturated_counts)) / g.size)


def frame_levels(
    gray, config: ExtractionConfig, *, stride=LEVEL_STRIDE, saturated_counts=SATURATED_COUNTS
) -> FrameLevels:
    """§3.1.1: the levels of a frame gray (H, W) before the N_max cap (``n_active`` 0)."""
    g = np.asarray(gray, np.float32)
    sub = level_subsample(g, stride=stride)
    bg, mad = background_and_mad(sub)
    sigma = noise_sigma(mad, bg)
    i_max = float(g.max())
    i_t = raw_threshold(bg, i_max, sigma, config)
    return FrameLevels(
        background=bg,
        noise_sigma=sigma,
        i_max=i_max,
        raw_threshold=i_t,
        peak_threshold=peak_threshold(bg, i_max, i_t, config),
        saturated_fraction=saturated_fraction(g, saturated_counts=saturated_counts),
        dark_level=dark_level(sub, bg),
    )


def active_pixel_set(gray, levels: FrameLevels, *, n_max) -> tuple[np.ndarray, FrameLevels]:
    """The active pixel set A (§3.1.1, B1): the pixels at or above I_t; when more than
    N_max, I_t rises to the (n - N_max)-th smallest active value (0-based), so that the
    dimmest go first and N_max stay (more where the cut value is shared). Returns A (H,
    W) bool and the levels as applied (I_t the cut, ``n_active`` the size of A)."""
    g = np.asarray(gray, np.float32)
    threshold = levels.raw_threshold
    mask = g >= np.float32(threshold)
    n = int(np.count_nonzero(mask))
    if n > n_max:
        threshold = float(np.sort(g[mask])[n - n_max])
        mask = g >= np.float32(threshold)
    return mask, levels._replace(raw_threshold=threshold, n_active=int(np.count_nonzero(mask)))


# -- §3.1.2-§3.2: components and the criteria -----------------------------------------------


def connected_components(mask) -> tuple[np.ndarray, np.ndarray]:
    """The 8-connected components of A (H, W): labels (H, W) int32 (0 outside A) and
    stats (K, 5) (x, y, w, h, area) per label, as ``cv2.connectedComponentsWithStats``
    numbers them (label 0 is the background)."""
    _, labels, stats, _ = cv2.connectedComponentsWithStats(
        np.asarray(mask, np.uint8), connectivity=8
    )
    return labels, stats


def touches_border(bbox, shape) -> bool:
    """A component whose box reaches the image's edge (H, W): its centroid would be
    biased."""
    x, y, w, h = bbox
    return x == 0 or y == 0 or x + w == shape[1] or y + h == shape[0]


def median_range_mm(distance, pixels) -> float:
    """A component's range: the median (float32, NumPy's) of its pixels' valid distances
    (H, W), NaN when none is valid."""
    d = np.asarray(distance, np.float32).ravel()[pixels]
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else float("nan")


def equivalent_diameter_px(area_px) -> float:
    """The diameter of a disc of ``area_px`` pixels."""
    return float(2.0 * np.sqrt(area_px / np.pi))


def window_moments(gray, bbox, *, pad=WINDOW_PAD_PX) -> tuple[float, float]:
    """(flux, m2) of a component over its box grown by ``pad`` (clipped to the frame),
    without a threshold: the excess over the median of the window's border (its first
    and last rows, then its first and last columns between them), where positive; flux
    its sum (counts), m2 the mean of its two axes' variances (px^2; NaN without flux)."""
    h, w = gray.shape
    x, y, bw, bh = bbox
    y0, y1 = max(y - pad, 0), min(y + bh + pad, h)
    x0, x1 = max(x - pad, 0), min(x + bw + pad, w)
    win = np.asarray(gray, np.float32)[y0:y1, x0:x1]
    border = np.concatenate((win[0], win[-1], win[1:-1, 0], win[1:-1, -1]))
    excess = np.maximum(win.astype(float) - float(np.median(border)), 0.0)
    flux = float(excess.sum())
    if flux <= 0:
        return flux, float("nan")
    yy, xx = np.mgrid[y0:y1, x0:x1]
    cu, cv = (excess * xx).sum() / flux, (excess * yy).sum() / flux
    return flux, float(0.5 * (excess * ((xx - cu) ** 2 + (yy - cv) ** 2)).sum() / flux)


def psf_variance_px2(m2, rho, use, *, fx, d_min_mm, max_sigma_px=MAX_PSF_SIGMA_PX) -> float:
    """The frame's lens PSF variance (px^2 per axis): the smallest, over the used
    components with a range and moments, of ``m2 - r^2 / 4 - 1/12`` (a disc of the
    catalog's smallest diameter at its range has r^2/4 per axis, a pixel 1/12), leaving
    out values above ``max_sigma_px^2`` (discs larger than the catalog's); at least 0, and
    0 when none is left. m2, rho (mm), use (n,)."""
    m2, rho = np.asarray(m2, float), np.asarray(rho, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.asarray(use, bool) & np.isfinite(m2) & np.isfinite(rho) & (rho > 0)
        r_px = 0.5 * fx * d_min_mm / rho[ok]
        var = m2[ok] - 0.25 * r_px**2 - 1.0 / 12.0
    var = var[var <= max_sigma_px**2]
    return max(float(var.min()), 0.0) if len(var) else 0.0


def blob_brightness(peak, flux, m2, rho, *, blur_var_px2, fx, d_min_mm, background) -> float:
    """The level criterion 1 (Eq. 16) credits a component with: the larger of its peak
    and its surface brightness ``bg + flux / A``, A the area of the disc its moments
    leave with the PSF taken out (pi r^2, r^2 = 4 (m2 - sigma^2 - 1/12)), at least the
    catalog's smallest disc face-on at its range ``rho`` (mm); the peak without a range
    or moments."""
    if not (np.isfinite(rho) and rho > 0 and np.isfinite(m2)):
        return float(peak)
    a_min = 0.25 * np.pi * (fx * d_min_mm / rho) ** 2
    a_disc = max(a_min, 4.0 * np.pi * (m2 - blur_var_px2 - 1.0 / 12.0))
    return max(float(peak), background + flux / a_disc)


def blur_widening_px(d_sharp_px, blur_var_px2, peak_contrast, threshold_contrast) -> float:
    """How much wider (px) a disc of ``d_sharp_px`` reads in A through a Gaussian PSF of
    ``blur_var_px2``: the blurred disc as a Gaussian of variance sigma^2 + d^2/16 + 1/12
    and peak ``peak_contrast`` cut at ``threshold_contrast`` (both over the background)
    is ``2 sqrt(2 v ln(peak / threshold))`` across; that with the PSF minus that without
    (0 without blur or a peak above the threshold)."""
    if blur_var_px2 <= 0 or peak_contrast <= threshold_contrast or threshold_contrast <= 0:
        return 0.0
    sharp = d_sharp_px**2 / 16.0 + 1.0 / 12.0
    cut = 2.0 * np.log(peak_contrast / threshold_contrast)
    return 2.0 * (np.sqrt(cut * (sharp + blur_var_px2)) - np.sqrt(cut * sharp))


def diameter_window_px(
    distance_mm, *, fx, diameters_mm, config: ExtractionConfig, widening_px=0.0
) -> tuple[float, float]:
    """Our size window (§3.2, in place of H_min..H_max): (d_lo, d_hi) px at a component's
    range. The catalog's discs face-on are ``fx D / rho``; the smallest shrinks by
    sqrt(cos(max tilt)) (the equivalent diameter of an ellipse of axes d and d cos t) and
    the tolerance and margin, at least 1 px; the largest grows by the tolerance and the
    larger of the margin and ``widening_px`` (``blur_widening_px``). (0, inf) without a
    range."""
    if not (np.isfinite(distance_mm) and distance_mm > 0):
        return 0.0, float("inf")
    face = fx * np.asarray(diameters_mm, float) / distance_mm
    cos_t = np.cos(np.radians(config.max_tilt_deg))
    d_lo = face.min() * np.sqrt(cos_t) / config.size_tolerance - config.size_margin_px
    d_hi = face.max() * config.size_tolerance + max(config.size_margin_px, widening_px)
    return max(float(d_lo), 1.0), float(d_hi)


def size_gate(
    area_px,
    extent_px,
    distance_mm,
    *,
    fx,
    diameters_mm,
    config: ExtractionConfig,
    widening_px=0.0,
) -> SizeVerdict:
    """The size window (§3.2) on a component of ``area_px`` pixels whose box spans
    ``extent_px`` at most. The paper's: ``H_min <= area <= H_max`` (``config.h_min_px``
    set; too big above H_max). Ours (``diameter_window_px``): the equivalent diameter and
    the extent within (d_lo, d_hi + 1 for the extent); too big when either is above."""
    d_eq = equivalent_diameter_px(area_px)
    if config.h_min_px is not None:
        hi_a = config.h_max_px if config.h_max_px is not None else np.inf
        inside, too_big = config.h_min_px <= area_px <= hi_a, area_px > hi_a
        return SizeVerdict(
            d_eq,
            equivalent_diameter_px(config.h_min_px),
            equivalent_diameter_px(hi_a),
            bool(inside),
            bool(too_big),
        )
    d_lo, d_hi = diameter_window_px(
        distance_mm, fx=fx, diameters_mm=diameters_mm, config=config, widening_px=widening_px
    )
    too_big = d_eq > d_hi or extent_px > d_hi + 1
    inside = d_lo <= d_eq <= d_hi and d_lo <= extent_px <= d_hi + 1
    return SizeVerdict(d_eq, d_lo, d_hi, bool(inside), bool(too_big))


def nlog_response(image, sigma_px, *, normalise=True) -> np.ndarray:
    """The negative Laplacian of Gaussian g = (-nabla^2 G) * f (Eqs. 11-14) of an image
    (h, w) float32, zero outside it: OpenCV's Gaussian (kernel 2 ceil(3 sigma) + 1) then
    its 4-neighbour Laplacian, in float32. With ``normalise`` scale-normalised (times
    sigma^2): a disc of contrast C at its matched scale sigma = r / sqrt(2) gives about
    2/e C at its centre, whatever its size. Returns (h, w) float32."""
    ksize = 2 * int(np.ceil(3.0 * sigma_px)) + 1
    smooth = cv2.GaussianBlur(
        np.asarray(image, np.float32), (ksize, ksize), sigma_px, borderType=cv2.BORDER_CONSTANT
    )
    lap = cv2.Laplacian(smooth, cv2.CV_32F, ksize=1, borderType=cv2.BORDER_CONSTANT)
    return -lap * np.float32(sigma_px**2 if normalise else 1.0)


def nlog_criteria(area_px, peak, background, config: ExtractionConfig):
    """The nLoG's scale and thresholds for a component: (sigma px, normalise, J_peak,
    J_t). The paper's (``config.nlog_sigma_px`` set): its fixed sigma, unnormalised, the
    absolute J_peak (Eq. 17) and J_t (Eq. 18). Ours: sigma = r_eq / sqrt(2) (at least
    0.5), scale-normalised, J_peak and J_t fractions of the component's peak contrast."""
    if config.nlog_sigma_px is not None:
        return config.nlog_sigma_px, False, config.nlog_peak_abs, config.nlog_floor_abs
    sigma = max(0.5, np.sqrt(area_px / np.pi) / np.sqrt(2.0))
    contrast = peak - background
    return sigma, True, config.nlog_peak_rel * contrast, config.nlog_floor_rel * contrast


def nlog_gate(
    gray, labels, label, *, bbox, area_px, peak, background, config: ExtractionConfig
) -> np.ndarray | None:
    """Criterion 2 (B3, B4; Eqs. 17-18) on component ``label`` of labels (H, W): its nLoG
    response on A's pixels of it alone (every other pixel zero, §3.1.2), over its box
    grown by ``NLOG_PAD_PX``, must reach J_peak on one of its pixels (Eq. 17); its pixels
    at or above J_t (Eq. 18, in float32) are the blob. Returns those pixels, (n,) int64
    flat indices sorted, or None when it is refused."""
    h, w = gray.shape
    x, y, bw, bh = bbox
    y0, y1 = max(y - NLOG_PAD_PX, 0), min(y + bh + NLOG_PAD_PX, h)
    x0, x1 = max(x - NLOG_PAD_PX, 0), min(x + bw + NLOG_PAD_PX, w)
    member = labels[y0:y1, x0:x1] == label
    patch = np.where(member, np.asarray(gray, np.float32)[y0:y1, x0:x1], np.float32(0))
    sigma, normalise, j_peak, j_t = nlog_criteria(area_px, peak, background, config)
    j = nlog_response(patch, sigma, normalise=normalise)
    keep = member & (j >= np.float32(j_t))
    if float(j[member].max()) < j_peak or not keep.any():
        return None
    rows, cols = np.nonzero(keep)
    return ((rows + y0) * w + cols + x0).astype(np.int64)


def moment_weights(values, background) -> np.ndarray:
    """The moment centroid's weights: ``max(I - bg, 1)`` per pixel, in float32 as the
    frame (values (n,) float32). Returns (n,) float64."""
    v = np.asarray(values, np.float32)
    return np.maximum(v - np.float32(background), np.float32(1.0)).astype(float)


def moment_centroid(us, vs, weights) -> tuple[np.ndarray, float]:
    """Eq. 19's weighted centroid (u, v) of points (n,) and the eccentricity of their
    weighted second moments, ``sqrt(1 - l2 / l1)`` (l1 >= l2 the covariance's
    eigenvalues; 0 when l1 is ~0)."""
    us, vs, wt = (np.asarray(a, float) for a in (us, vs, weights))
    cu, cv = (wt * us).sum() / wt.sum(), (wt * vs).sum() / wt.sum()
    du, dv = us - cu, vs - cv
    cov = (
        np.array(
            [
                [(wt * du * du).sum(), (wt * du * dv).sum()],
                [(wt * du * dv).sum(), (wt * dv * dv).sum()],
            ]
        )
        / wt.sum()
    )
    l2, l1 = np.linalg.eigvalsh(cov)
    ecc = float(np.sqrt(max(0.0, 1.0 - l2 / l1))) if l1 > 1e-12 else 0.0
    return np.array([cu, cv]), ecc


def max_eccentricity(max_tilt_deg) -> float:
    """The eccentricity of a disc's image tilted by ``max_tilt_deg``: sin(tilt)."""
    return float(np.sqrt(1.0 - np.cos(np.radians(max_tilt_deg)) ** 2))


def shape_gate(n_pixels, eccentricity, max_eccentricity) -> bool:
    """The shape criterion: a blob of at least ``SHAPE_MIN_PIXELS`` is no more eccentric
    than a disc tilted by the largest accepted angle; a smaller one has no measurable
    shape and passes."""
    return bool(n_pixels < SHAPE_MIN_PIXELS or eccentricity <= max_eccentricity)


def penalty_score(
    area_px,
    eccentricity,
    distance_mm,
    brightness,
    *,
    fx,
    diameters_mm,
    i_peak,
    i_t,
    max_eccentricity,
) -> float:
    """The penalty score q in [0, 1] (§3.4; the paper does not define it):
    ``1 - (1 - q_size)(1 - q_shape)(1 - q_int)``. q_size: the smallest
    ``|ln(d_eq / (fx D / rho))| / ln 3`` over the catalog's D, clipped to [0, 1] (0 under a
    3 px blob or without a range); q_shape: ``(e / e_max)^2`` clipped (0 under
    ``SHAPE_MIN_PIXELS``); q_int: how far the brightness criterion 1 credits
    (``blob_brightness``) falls short of I_peak, over I_peak - I_t, clipped (0 on every
    component ``find_candidates`` scores: criterion 1 has passed them)."""
    d_eq = equivalent_diameter_px(area_px)
    q_size = 0.0
    if np.isfinite(distance_mm) and distance_mm > 0 and d_eq >= 3.0:
        predicted = fx * np.asarray(diameters_mm, float) / distance_mm
        q_size = float(np.clip(np.abs(np.log(d_eq / predicted)).min() / np.log(3.0), 0, 1))
    q_shape = 0.0
    if area_px >= SHAPE_MIN_PIXELS:
        q_shape = float(np.clip(eccentricity / max(max_eccentricity, 1e-6), 0, 1)) ** 2
    q_int = float(np.clip((i_peak - brightness) / max(i_peak - i_t, 1e-6), 0, 1))
    return 1.0 - (1.0 - q_size) * (1.0 - q_shape) * (1.0 - q_int)


def rank_candidates(blobs, max_candidates) -> tuple[list, list]:
    """The L best (``max_candidates``): blobs sorted by penalty, then by peak (brightest
    first; ties keep their order). Returns (the L best, the rest), both in that order."""
    ranked = sorted(blobs, key=lambda b: (b.penalty, -b.peak_counts))
    return ranked[:max_candidates], ranked[max_candidates:]


# -- the chain --------------------------------------------------------------------------------


class _Component(NamedTuple):
    label: int
    pixels: np.ndarray
    area_px: int
    bbox: tuple[int, int, int, int]
    peak: float


def _components(gray, mask, min_area_px) -> tuple[np.ndarray, list[_Component]]:
    """A's labels (H, W) and its components of at least ``max(min_area_px, 1)`` pixels,
    in label order."""
    labels, stats = connected_components(mask)
    out = []
    flat_labels = labels.ravel()
    for k in range(1, len(stats)):
        if stats[k, cv2.CC_STAT_AREA] < max(min_area_px, 1):
            continue
        pixels = np.flatnonzero(flat_labels == k)
        out.append(
            _Component(
                k,
                pixels,
                int(stats[k, cv2.CC_STAT_AREA]),
                (int(stats[k, 0]), int(stats[k, 1]), int(stats[k, 2]), int(stats[k, 3])),
                float(gray.ravel()[pixels].max()),
            )
        )
    return labels, out


def _box_centre(c: _Component, reason: str) -> Rejected:
    x, y, bw, bh = c.bbox
    return Rejected(x + (bw - 1) / 2, y + (bh - 1) / 2, equivalent_diameter_px(c.area_px), reason)


def find_candidates(
    gray, distance_mm, levels: FrameLevels, *, fx, diameters_mm, config: ExtractionConfig
) -> Candidates:
    """§3.1.2-§3.2: the candidate blobs of a frame, gray and distance_mm (H, W), with
    ``levels`` from ``frame_levels``; fx px; diameters_mm (N,) the catalog's.

    A (``active_pixel_set``), its components (``connected_components``); per component
    of at least ``min_area_px``: "border" (``touches_border``); its range
    (``median_range_mm``); criterion 1 (Eq. 16, B2): the paper's window tests its peak
    against I_peak, ours the brightness ``blob_brightness`` credits it with under the
    frame's PSF (``window_moments``, ``psf_variance_px2`` read twice: from the components
    bright by their peak, then from those bright by that brightness), else "dim"; the
    size window (``size_gate``, widened by ``blur_widening_px``): "oversize" (kept for
    §3.3) or "size"; criterion 2 (``nlog_gate``): "nlog"; the moment centroid of the
    pixels it keeps (``moment_centroid``); "shape" (``shape_gate``); "penalty" (q of
    ``penalty_score`` above ``q_max``); then the L best (``rank_candidates``), the rest
    "rank"."""
    g = np.asarray(gray, np.float32)
    d = np.asarray(distance_mm, np.float32)
    mask, levels = active_pixel_set(g, levels, n_max=config.n_max)
    labels, components = _components(g, mask, config.min_area_px)
    bg, i_peak, i_t = levels.background, levels.peak_threshold, levels.raw_threshold
    d_min = float(np.min(diameters_mm))
    inner = [c for c in components if not touches_border(c.bbox, g.shape)]
    rho = {c.label: median_range_mm(d, c.pixels) for c in inner}
    brightness = {c.label: c.peak for c in components}
    blur_var = 0.0
    if config.h_min_px is None:  # ours: criterion 1 also on surface brightness
        moments = {c.label: window_moments(g, c.bbox) for c in inner}
        m2 = [moments[c.label][1] for c in inner]
        rhos = [rho[c.label] for c in inner]
        common = {"fx": fx, "d_min_mm": d_min}
        blur_var = psf_variance_px2(m2, rhos, [c.peak >= i_peak for c in inner], **common)
        for c in inner:
            brightness[c.label] = blob_brightness(
                c.peak,
                *moments[c.label],
                rho[c.label],
                blur_var_px2=blur_var,
                background=bg,
                **common,
            )
        blur_var = psf_variance_px2(
            m2, rhos, [brightness[c.label] >= i_peak for c in inner], **common
        )
    e_max = max_eccentricity(config.max_tilt_deg)
    accepted, oversize, rejected, wrong_size = [], [], [], []
    for c in components:
        if touches_border(c.bbox, g.shape) or brightness[c.label] < i_peak:
            rejected.append(_box_centre(c, "border" if touches_border(c.bbox, g.shape) else "dim"))
            continue
        r = rho[c.label]
        widening = 0.0
        if np.isfinite(r) and r > 0:
            d_sharp = fx * np.max(diameters_mm) / r * config.size_tolerance
            widening = blur_widening_px(d_sharp, blur_var, c.peak - bg, i_t - bg)
        size = size_gate(
            c.area_px,
            max(c.bbox[2:]),
            r,
            fx=fx,
            diameters_mm=diameters_mm,
            config=config,
            widening_px=widening,
        )
        if not size.inside:
            wrong_size.append(WrongSize(*size[:3], r))
        if size.too_big:
            oversize.append(OversizeBlob(c.pixels, c.area_px, c.bbox, c.peak, r))
            rejected.append(_box_centre(c, "oversize"))
            continue
        if not size.inside:
            rejected.append(_box_centre(c, "size"))
            continue
        kept = nlog_gate(
            g,
            labels,
            c.label,
            bbox=c.bbox,
            area_px=c.area_px,
            peak=c.peak,
            background=bg,
            config=config,
        )
        if kept is None:
            rejected.append(_box_centre(c, "nlog"))
            continue
        rows, cols = np.divmod(kept, g.shape[1])
        uv, ecc = moment_centroid(cols, rows, moment_weights(g.ravel()[kept], bg))
        if not shape_gate(len(kept), ecc, e_max):
            rejected.append(_box_centre(c, "shape"))
            continue
        q = penalty_score(
            len(kept),
            ecc,
            r,
            brightness[c.label],
            fx=fx,
            diameters_mm=diameters_mm,
            i_peak=i_peak,
            i_t=i_t,
            max_eccentricity=e_max,
        )
        if q > config.q_max:
            rejected.append(_box_centre(c, "penalty"))
            continue
        accepted.append(CandidateBlob(kept, len(kept), c.bbox, uv, r, c.peak, ecc, q))
    best, beyond = rank_candidates(accepted, config.max_candidates)
    rejected += [
        Rejected(
            float(b.centroid_uv[0]),
            float(b.centroid_uv[1]),
            equivalent_diameter_px(b.area_px),
            "rank",
        )
        for b in beyond
    ]
    return Candidates(
        tuple(best),
        tuple(oversize),
        tuple(rejected),
        tuple(wrong_size),
        levels,
        float(np.sqrt(blur_var)),
        mask,
    )
