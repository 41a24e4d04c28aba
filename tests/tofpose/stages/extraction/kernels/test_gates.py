"""Criterion 1 and the size window under lens blur (``kernels.gates``): the window
moments against their NumPy statement, the PSF read back from blobs of known blur, the
surface brightness that credits an unresolved reflector and not a dim patch, and the
widening of the size window."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from tofpose.stages.extraction.constants import WINDOW_PAD_PX
from tofpose.stages.extraction.kernels.gates import (
    blob_brightness,
    blur_widening_px,
    psf_variance_px2,
    window_moments,
)


def blurred_disc(shape, centre_uv, radius_px, sigma_px, peak_counts, level=100.0):
    """(H, W) float32: a disc of ``radius_px`` and surface brightness ``peak_counts``
    over ``level`` (pixel centres at integer coordinates), through a Gaussian PSF of
    ``sigma_px``, integrated over each pixel: drawn on a grid 8 x finer, blurred there
    (``scipy.ndimage.gaussian_filter``) and summed back to pixels."""
    k = 8
    h, w = shape
    ys, xs = np.mgrid[0 : h * k, 0 : w * k]
    u, v = (xs + 0.5) / k - 0.5, (ys + 0.5) / k - 0.5
    fine = (np.hypot(u - centre_uv[0], v - centre_uv[1]) <= radius_px).astype(float)
    if sigma_px > 0:
        fine = gaussian_filter(fine, sigma_px * k, mode="constant", truncate=5.0)
    pixels = fine.reshape(h, k, w, k).mean(axis=(1, 3))
    return (level + peak_counts * pixels).astype(np.float32)


def test_window_moments_are_the_numpy_statement():
    rng = np.random.default_rng(3)
    gray = rng.normal(100.0, 5.0, (40, 50)).astype(np.float32)
    gray[10:14, 20:23] += 800.0
    gray[30:32, 5:9] += 300.0
    bbox = np.array([[0, 0, 0, 0], [20, 10, 3, 4], [5, 30, 4, 2]], np.int64)
    flux, m2 = window_moments(gray, bbox, np.array([1, 2], np.int64))
    for j, (x, y, bw, bh) in enumerate(bbox[1:]):
        p = WINDOW_PAD_PX
        y0, y1, x0, x1 = max(y - p, 0), min(y + bh + p, 40), max(x - p, 0), min(x + bw + p, 50)
        win = gray[y0:y1, x0:x1].astype(float)
        border = np.concatenate([win[0], win[-1], win[1:-1, 0], win[1:-1, -1]])
        wt = np.clip(win - np.median(border), 0, None)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        cu, cv = (wt * xx).sum() / wt.sum(), (wt * yy).sum() / wt.sum()
        ref = 0.5 * ((wt * ((xx - cu) ** 2 + (yy - cv) ** 2)).sum() / wt.sum())
        assert flux[j] == pytest.approx(wt.sum(), rel=1e-6)  # (the level in float32)
        assert m2[j] == pytest.approx(ref, rel=1e-6)


@pytest.mark.parametrize("sigma_px", [0.6, 1.0, 1.4])
def test_the_psf_is_read_back_from_an_unresolved_reflector(sigma_px):
    """A 35 mm disc at 8 m (0.71 px radius) blurred by a known PSF: the estimate is the
    PSF's variance within 15 %; a sharp one reads well under the size margin's blur."""
    fx, d_mm, rho = 325.0, 35.0, 8000.0
    r_px = 0.5 * fx * d_mm / rho
    gray = blurred_disc((30, 30), (14.3, 15.6), r_px, sigma_px, 2000.0)
    above = np.argwhere(gray > 100.0 + 0.15 * (gray.max() - 100.0))
    (y0, x0), (y1, x1) = above.min(0), above.max(0)
    bbox = np.array([[x0, y0, x1 - x0 + 1, y1 - y0 + 1]], np.int64)
    _, m2 = window_moments(gray, bbox, np.array([0], np.int64))
    var = psf_variance_px2(m2, np.array([rho]), np.array([True]), fx, d_mm)
    assert var == pytest.approx(sigma_px**2, rel=0.15)
    sharp = blurred_disc((30, 30), (14.3, 15.6), r_px, 0.0, 2000.0)
    _, m2 = window_moments(sharp, bbox, np.array([0], np.int64))
    assert psf_variance_px2(m2, np.array([rho]), np.array([True]), fx, d_mm) < 0.05
    # nothing used, or no range: no PSF read
    assert psf_variance_px2(m2, np.array([rho]), np.array([False]), fx, d_mm) == 0.0
    assert psf_variance_px2(m2, np.array([np.nan]), np.array([True]), fx, d_mm) == 0.0


def test_surface_brightness_credits_an_unresolved_reflector_and_not_a_dim_patch():
    """The blurred small disc's peak is a fifth of its surface brightness; its credit is
    close to the surface brightness. A 6 x 6 patch at 300 counts through the same PSF
    is credited 300."""
    fx, d_mm, rho, sigma = 325.0, 35.0, 8000.0, 1.3
    r_px = 0.5 * fx * d_mm / rho
    disc = blurred_disc((30, 30), (14.5, 15.0), r_px, sigma, 2000.0)
    patch = np.zeros((30, 30))
    patch[12:18, 12:18] = 300.0
    patch = (100.0 + gaussian_filter(patch, sigma, mode="constant")).astype(np.float32)
    for gray, bbox, expect in (
        (disc, [11, 12, 7, 7], 2000.0),
        (patch, [11, 11, 8, 8], 300.0),
    ):
        b = np.array([bbox], np.int64)
        flux, m2 = window_moments(gray, b, np.array([0], np.int64))
        peak = np.array([float(gray.max())])
        credit = blob_brightness(peak, flux, m2, np.array([rho]), sigma**2, fx, d_mm, 100.0)
        assert credit[0] - 100.0 == pytest.approx(expect, rel=0.2)
    assert disc.max() - 100.0 < 0.25 * 2000.0  # the peak alone would call it dim


def test_the_size_window_widens_with_the_psf_only():
    assert blur_widening_px(4.4, 0.0, 2400.0, 360.0) == 0.0
    assert blur_widening_px(4.4, 2.0, 300.0, 360.0) == 0.0  # peak under the threshold
    w = [blur_widening_px(4.4, v, 2400.0, 360.0) for v in (0.1, 0.5, 1.0, 2.0)]
    assert np.all(np.diff(w) > 0)
    # the widening of a Gaussian's diameter at the cut, from sigma = 0 to sigma
    cut = 2 * np.log(2400.0 / 360.0)
    sharp = 4.4**2 / 16 + 1 / 12
    assert w[-1] == pytest.approx(2 * (np.sqrt(cut * (sharp + 2.0)) - np.sqrt(cut * sharp)))


def test_discs_larger_than_the_catalog_are_not_read_as_blur():
    """200 mm discs at 2 m with the paper catalog (35 mm smallest): their moments say
    their size, not a PSF, so the window stays the sharp one."""
    fx, rho = 325.0, 2000.0
    gray = blurred_disc((60, 60), (29.5, 30.0), 0.5 * fx * 200.0 / rho, 0.0, 2000.0)
    _, m2 = window_moments(gray, np.array([[13, 14, 33, 33]], np.int64), np.array([0]))
    assert psf_variance_px2(m2, np.array([rho]), np.array([True]), fx, 35.0) == 0.0
