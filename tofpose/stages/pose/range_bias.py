"""The camera's range bias learned over a recording (empirical Bayes).

A frame's pose fit estimates a range offset common to its reflectors under a prior
N(0, sigma_b^2) (``PipelineConfig.range_bias_sigma_mm``: 15 mm for a camera of unknown
calibration). One frame can tell that offset only through the image scale, which at a
few metres is noisy: on a calibrated camera (no offset) the per-frame estimate is then
what spreads the position along the line of sight. Many frames of one camera tell more:
each frame's likelihood of the offset (its posterior with the prior divided out,
``RangeOffset.likelihood``: mean ``m_k``, variance ``v_k``) is a draw ``m_k ~ N(mu,
tau^2 + v_k)`` when the offsets of the camera's frames spread by ``tau`` about a mean
``mu``. Both are estimated by maximum likelihood over the frames; the frames are then
measured again with the prior N(mu, tau^2 + se(tau^2) + var(mu)) (the spread's upper
one-sigma value and the mean's own uncertainty): near N(0, ~0) on a calibrated camera
(the ranges are then trusted and the position follows them); a constant offset is
learned and taken out; one that changes with range or amplitude stays covered by the
spread.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from tofpose.stages.pose.records import RangeOffset

#: frames a recording's spread is learned from (``io.camera_file.learned_range_bias``):
#: spaced over it, so that a long recording costs no more than a short one
RECORDING_FRAMES = 64
#: fewest frames whose fit says something of the offset before a spread is learned
MIN_FRAMES = 8
#: a frame whose offset is beyond this quantile of chi-square(1) under the spread so far
#: is left out (a wrong pose, a frame of another camera): 1 in 10^4 of good frames
OUTLIER_P = 0.9999
#: fixed-point iterations of the maximum-likelihood spread (converges in a few)
ITERATIONS = 100
TOLERANCE_MM2 = 1e-9


@dataclass(frozen=True)
class LearnedRangeBias:
    """The offsets of a camera's frames over a recording (``learn_range_bias``).

    mean_mm : their maximum-likelihood mean ``mu``, mm: the prior's mean to measure the
        frames with (``PipelineConfig.range_offset_mean_mm``).
    sigma_mm : the prior's sigma: ``sqrt(tau^2 + se(tau^2) + var(mu))``, capped at the
        configured one unless the frames show more (``prior_sigma_mm``).
    tau_mm : the maximum-likelihood spread of the offsets about ``mu``; tau2_se_mm2 : the
        standard error of its square; mean_se_mm : the standard error of ``mu`` (inverse
        Fisher information, both).
    n_frames : the frames it was learned from; n_outliers : those left out as beyond the
        spread (frames whose offset is not finite are not counted: they tell nothing).
    """

    mean_mm: float
    sigma_mm: float
    tau_mm: float
    tau2_se_mm2: float
    mean_se_mm: float
    n_frames: int
    n_outliers: int

    def wider_than(self, configured_sigma_mm: float) -> bool:
        """Whether the frames show offsets spread wider than ``configured_sigma_mm`` beyond
        doubt: ``tau^2`` more than two of its standard errors above its square."""
        return self.tau_mm**2 - 2.0 * self.tau2_se_mm2 > configured_sigma_mm**2

    def prior_sigma_mm(self, configured_sigma_mm: float) -> float:
        """The prior sigma to measure the frames with in place of ``configured_sigma_mm``:
        the learned one, but never wider than the configured one unless the frames show a
        wider spread beyond doubt (``wider_than``): frames that tell the offset poorly
        (small or far targets) leave a large ``se(tau^2)``, which must not widen a prior
        a range calibration made narrow."""
        if self.wider_than(configured_sigma_mm):
            return self.sigma_mm
        return min(self.sigma_mm, configured_sigma_mm)

    def summary(self, configured_sigma_mm: float, calibrated_sigma_mm: float) -> str:
        """One line: what was learned, and the prior the frames are measured with in
        place of the configured sigmas (uncalibrated, and inside a range correction's
        span: ``prior_sigma_mm`` of each)."""
        used = self.prior_sigma_mm(configured_sigma_mm)
        used_cal = self.prior_sigma_mm(calibrated_sigma_mm)
        sigma, sigma_cal = f"{used:.1f}", f"{used_cal:.1f}"
        sigma = f"sigma {sigma} mm" + (
            f" ({sigma_cal} mm inside a range correction's span)" if sigma_cal != sigma else ""
        )
        return (
            f"range bias learned over {self.n_frames} frames: offset "
            f"{self.mean_mm:+.1f} +- {self.mean_se_mm:.1f} mm, spread {self.tau_mm:.1f} mm; "
            f"prior {self.mean_mm:+.1f} mm, {sigma}"
            + (f"; {self.n_outliers} frame(s) left out" if self.n_outliers else "")
        )


def _mean_and_spread(m: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """The maximum-likelihood (mu, tau^2) of ``m ~ N(mu, tau^2 + v)`` (m, v: (n,)), by
    the score equations' fixed point: ``mu = sum w m / sum w``, ``tau^2 = sum w^2 ((m -
    mu)^2 - v) / sum w^2`` clipped at 0, w = 1 / (v + tau^2)."""
    tau2 = 0.0
    mu = 0.0
    for _ in range(ITERATIONS):
        w = 1.0 / (v + tau2)
        mu = float(np.sum(w * m) / np.sum(w))
        new = max(0.0, float(np.sum(w**2 * ((m - mu) ** 2 - v)) / np.sum(w**2)))
        if abs(new - tau2) < TOLERANCE_MM2:
            tau2 = new
            break
        tau2 = new
    w = 1.0 / (v + tau2)
    return float(np.sum(w * m) / np.sum(w)), tau2


def learn_range_bias(offsets: Iterable[RangeOffset]) -> LearnedRangeBias | None:
    """The mean and spread of the range offsets of frames of one camera (module
    docstring), from each frame's ``RangeOffset`` (those without a likelihood, whose fit
    could not tell the offset, are skipped); None with fewer than ``MIN_FRAMES`` that
    tell it."""
    pairs = [lk for lk in (o.likelihood() for o in offsets) if lk is not None]
    m = np.array([p[0] for p in pairs], float)
    v = np.array([p[1] for p in pairs], float)
    valid = np.isfinite(m) & np.isfinite(v) & (v > 0)  # a NaN offset tells nothing
    keep = valid.copy()
    if keep.sum() < MIN_FRAMES:
        return None
    limit = float(chi2.ppf(OUTLIER_P, 1))
    mu, tau2 = _mean_and_spread(m[keep], v[keep])
    while True:  # leave out the frames beyond the spread so far, until none is
        inside = keep & ((m - mu) ** 2 <= limit * (v + tau2))
        if inside.sum() == keep.sum() or inside.sum() < MIN_FRAMES:
            break
        keep = inside
        mu, tau2 = _mean_and_spread(m[keep], v[keep])
    w = 1.0 / (v[keep] + tau2)
    tau2_se = float(np.sqrt(2.0 / np.sum(w**2)))
    mean_var = float(1.0 / np.sum(w))
    if not (np.isfinite(mu) and np.isfinite(tau2) and np.isfinite(tau2_se + mean_var)):
        return None
    return LearnedRangeBias(
        mean_mm=mu,
        sigma_mm=float(np.sqrt(tau2 + tau2_se + mean_var)),
        tau_mm=float(np.sqrt(tau2)),
        tau2_se_mm2=tau2_se,
        mean_se_mm=float(np.sqrt(mean_var)),
        n_frames=int(keep.sum()),
        n_outliers=int(valid.sum() - keep.sum()),
    )
