"""The camera's range bias learned over a recording (empirical Bayes).

A frame's pose fit estimates a range offset common to its reflectors under a prior
N(0, sigma_b^2) (``PipelineConfig.range_bias_sigma_mm``: 15 mm for a camera of unknown
calibration). One frame can tell that offset only through the image scale, which at a
few metres is noisy: on a calibrated camera (no offset) the per-frame estimate is then
what spreads the position along the line of sight. Many frames of one camera tell more:
each frame's likelihood of the offset (its posterior with the prior divided out,
``RangeOffset.likelihood``: mean ``m_k``, variance ``v_k``) is a draw ``m_k ~ N(0, tau^2
+ v_k)`` when the offsets of the camera's frames spread by ``tau`` about 0. ``tau^2`` is
estimated by maximum likelihood over the frames, and the upper one-sigma value of that
estimate replaces ``sigma_b`` when the frames are measured again: near 0 on a calibrated
camera (the ranges are then trusted and the position follows them), about the offsets'
RMS on an uncalibrated one (a constant offset, or one that changes with range or
amplitude, stays covered). The spread is about 0, not about the offsets' mean: a common
mean would need the fit's prior to be re-centred (left for later).
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
    """The spread of a camera's range offsets over a recording (``learn_range_bias``).

    sigma_mm : the prior sigma to measure the frames with: ``sqrt(tau2 + tau2_se)``.
    tau_mm : the maximum-likelihood spread of the offsets about 0; tau2_se_mm2 : the
        standard error of its square (inverse Fisher information).
    n_frames : the frames it was learned from; n_outliers : those left out.
    mean_mm : the offsets' weighted mean (1 / (v_k + tau^2)), to read, not applied.
    """

    sigma_mm: float
    tau_mm: float
    tau2_se_mm2: float
    n_frames: int
    n_outliers: int
    mean_mm: float

    def summary(self) -> str:
        return (
            f"range bias learned over {self.n_frames} frames: offsets spread "
            f"{self.tau_mm:.1f} mm about 0 (mean {self.mean_mm:+.1f} mm), prior sigma "
            f"{self.sigma_mm:.1f} mm"
            + (f"; {self.n_outliers} frame(s) left out" if self.n_outliers else "")
        )


def _spread(m: np.ndarray, v: np.ndarray) -> float:
    """The maximum-likelihood tau^2 of ``m ~ N(0, tau^2 + v)`` (m, v: (n,)), by its
    score equation's fixed point ``tau^2 = sum w^2 (m^2 - v) / sum w^2``, w = 1 / (v +
    tau^2), clipped at 0."""
    tau2 = 0.0
    for _ in range(ITERATIONS):
        w2 = (1.0 / (v + tau2)) ** 2
        new = max(0.0, float(np.sum(w2 * (m**2 - v)) / np.sum(w2)))
        if abs(new - tau2) < TOLERANCE_MM2:
            return new
        tau2 = new
    return tau2


def learn_range_bias(offsets: Iterable[RangeOffset]) -> LearnedRangeBias | None:
    """The spread of the range offsets of frames of one camera (module docstring), from
    each frame's ``RangeOffset`` (those without a likelihood, whose fit could not tell the
    offset, are skipped); None with fewer than ``MIN_FRAMES`` that tell it."""
    pairs = [lk for lk in (o.likelihood() for o in offsets) if lk is not None]
    if len(pairs) < MIN_FRAMES:
        return None
    m = np.array([p[0] for p in pairs], float)
    v = np.array([p[1] for p in pairs], float)
    keep = np.isfinite(m) & np.isfinite(v) & (v > 0)
    limit = float(chi2.ppf(OUTLIER_P, 1))
    tau2 = _spread(m[keep], v[keep])
    while True:  # leave out the frames beyond the spread so far, until none is
        inside = keep & (m**2 <= limit * (v + tau2))
        if inside.sum() == keep.sum() or inside.sum() < MIN_FRAMES:
            break
        keep = inside
        tau2 = _spread(m[keep], v[keep])
    w = 1.0 / (v[keep] + tau2)
    se = float(np.sqrt(2.0 / np.sum(w**2)))
    return LearnedRangeBias(
        sigma_mm=float(np.sqrt(tau2 + se)),
        tau_mm=float(np.sqrt(tau2)),
        tau2_se_mm2=se,
        n_frames=int(keep.sum()),
        n_outliers=int(len(m) - keep.sum()),
        mean_mm=float(np.sum(w * m[keep]) / np.sum(w)),
    )
