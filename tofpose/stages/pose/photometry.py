"""Photometric consistency of a pose's matched reflectors (ours, beyond the paper's §5).

The reflectors of one target are one material on one plate: under one pose they return
about the same light per unit of disc area (their gains differ by some tens of per cent,
and the incidence fall-off is nearly the same across the plate). A match that pairs an
80 mm disc with a faint speck of noise and a 35 mm disc with the brightest blob of the
frame can still fit a rigid pose (four points at 8 m fit many poses), but not this: one
such pose at 8 m in the physics study (every knob drawn: blur, 10 klx ambient, a grey
plate) was 159 deg off with a covariance that claimed 0.2 deg (`docs/results.md`).

Each matched reflector's return is measured by aperture photometry around its centroid
(a disc of its predicted image radius plus a blur margin, the surround's median from an
annulus outside it taken off), divided by its predicted disc area in pixels. Apertures
with a saturated pixel (their flux is clipped) or too faint to measure (flux under
``MIN_APERTURE_SNR`` times its noise) are left out. Measured spread of the ratio of the
largest to the smallest, correct matches: at most 2.0 on the other renderer's far,
saturating and glint frames and 4.1 on its uncalibrated camera at 1 m; at most 5.1 over
the simulator's physics families at 1-8 m (reflector gains 0.7-1.3 and a fall-off
exponent of 2-6 drawn per frame), saturated apertures included. The wrong pose: 13.8.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a pose whose matched reflectors differ by more than this in return per disc area is
#: refused (the largest ratio of correct matches measured: 5.1, module docstring)
MAX_RADIANCE_RATIO = 8.0
#: an aperture is measured when its flux is at least this many times its noise
MIN_APERTURE_SNR = 3.0
#: the aperture's radius beyond the disc's predicted image radius (px): the lens blur's
#: tails (the gates adapt to a PSF of up to 2 px; most of its flux lies within 1.5)
APERTURE_MARGIN_PX = 1.5
#: the surround's annulus starts this far outside the aperture (px) ...
ANNULUS_GAP_PX = 1.0
#: ... and is this wide (px)
ANNULUS_WIDTH_PX = 2.0
#: a normal distribution's sigma per median absolute deviation
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class ApertureReturns:
    """The matched reflectors' returns, one row each (m,): ``flux_counts`` the aperture's
    summed counts above the surround's median; ``noise_counts`` its 1-sigma (the
    surround's robust spread times sqrt of the aperture's pixels); ``per_area`` flux over
    the disc's predicted image area (counts / px^2); ``saturated`` a pixel of the
    aperture at full scale."""

    flux_counts: np.ndarray
    noise_counts: np.ndarray
    per_area: np.ndarray
    saturated: np.ndarray

    @property
    def measured(self) -> np.ndarray:
        """(m,) bool: the apertures the consistency test uses (unsaturated, measurable)."""
        snr_ok = self.flux_counts >= MIN_APERTURE_SNR * self.noise_counts
        return ~self.saturated & snr_ok & (self.per_area > 0)


def aperture_returns(
    gray: np.ndarray, uv_px: np.ndarray, disc_radius_px: np.ndarray, full_scale_counts: float
) -> ApertureReturns:
    """Aperture photometry of m reflectors of the (H, W) ``gray`` frame at their
    centroids ``uv_px`` (m, 2), with predicted image radii ``disc_radius_px`` (m,) px;
    ``full_scale_counts`` the sensor's saturation level."""
    g = np.asarray(gray, dtype=np.float64)
    h, w = g.shape
    m = len(uv_px)
    flux, noise, per_area = np.zeros(m), np.full(m, np.inf), np.zeros(m)
    saturated = np.zeros(m, bool)
    for i in range(m):
        u, v = float(uv_px[i, 0]), float(uv_px[i, 1])
        r_ap = float(disc_radius_px[i]) + APERTURE_MARGIN_PX
        r_in = r_ap + ANNULUS_GAP_PX
        r_out = r_in + ANNULUS_WIDTH_PX
        v0, v1 = max(int(v - r_out) - 1, 0), min(int(v + r_out) + 2, h)
        u0, u1 = max(int(u - r_out) - 1, 0), min(int(u + r_out) + 2, w)
        if v0 >= v1 or u0 >= u1:
            continue
        rows, cols = np.mgrid[v0:v1, u0:u1]
        d = np.hypot(cols - u, rows - v)
        window = g[v0:v1, u0:u1]
        inside = d < r_ap
        ring = window[(d >= r_in) & (d < r_out)]
        if not inside.any() or ring.size < 4:
            continue
        level = float(np.median(ring))
        spread = MAD_TO_SIGMA * float(np.median(np.abs(ring - level)))
        flux[i] = float(np.sum(window[inside] - level))
        noise[i] = max(spread, 1.0) * float(np.sqrt(inside.sum()))
        per_area[i] = flux[i] / (np.pi * float(disc_radius_px[i]) ** 2)
        saturated[i] = bool(np.any(window[inside] >= full_scale_counts))
    return ApertureReturns(flux, noise, per_area, saturated)


def radiance_ratio(returns: ApertureReturns) -> tuple[float, int, int]:
    """The largest return per disc area over the smallest among the measured apertures,
    with the rows of the two (NaN, -1, -1 with fewer than two measured)."""
    rows = np.flatnonzero(returns.measured)
    if len(rows) < 2:
        return float("nan"), -1, -1
    b = returns.per_area[rows]
    hi, lo = rows[int(np.argmax(b))], rows[int(np.argmin(b))]
    return float(returns.per_area[hi] / returns.per_area[lo]), int(hi), int(lo)
