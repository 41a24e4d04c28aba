"""Centres of two reflectors imaged as one blob, by fitting a model of the pixels.

Ours (not in the paper). Beyond ~6 m markers 7 and 8 of the paper target (80 mm discs
90 mm apart) are ~4 px discs a fraction of a pixel apart: integrated over the pixel area
and blurred by the lens, their light does not dip between them. Cut in two
(``confirmation.split_in_two``), each half keeps the neighbour's light at the cut and its
moment centroid is pulled towards the other by ~0.1 px; both pull the same way along the
pair, which shortens the pattern at that end: a tilt no averaging removes. So the
centres come from a fit of the pixels around the pair instead:

    I(p) = bg + sum_k a_k C(p; c_k, r, s),
    C(p; c, r, s) = mean over the pixel's area of 1/2 erfc((|q - c| - r) / (sqrt 2 s))

two discs of a common radius r (the pair's markers have one diameter) with an edge
blurred by a Gaussian of sigma s (the lens PSF; the erfc edge is the blurred disc for
r >> s, close enough at r ~ 2 px), amplitudes a_k (reflector gains differ), a local
level bg (a plate that is not black), integrated over each pixel by 3 x 3 sub-samples.
A compiled Levenberg-Marquardt loop (``kernels.pair_fit``; SciPy's ``least_squares`` in
``fit_pair_reference`` is its oracle) fits the 9 parameters on the pixels of the pair's
box grown by ``MARGIN_PX`` (the surround fixes bg and the edge). The centres' sigmas from the fit's
covariance (scaled by its residual variance) are diagnostic: they hold the pixel noise
only, not the model's error (the PSF's real shape, the surround's mixing), so the
measurement keeps the split's own centroid sigma (``uncertainty.SPLIT_CENTROID_PX``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.stages.ellipses.arithmetic import COMPILED, EllipsesArithmetic

#: pixels around the pair's box included in the fit (the surround: level and edges)
MARGIN_PX = 2
#: sub-samples per pixel side for the pixel-area integration
SUBSAMPLES = 3
#: bounds of the edge blur sigma, px
BLUR_BOUNDS_PX = (0.05, 2.0)
#: the fitted radius may differ from the starting one by this factor either way
RADIUS_FACTOR = 1.6
#: function evaluations of the fit (it converges in ~5-15 from the 2-means centres)
MAX_EVALUATIONS = 200
#: a step moving no centre by more than this has converged (the centres' noise is
#: ~0.02-0.05 px), px
CENTRE_TOLERANCE_PX = 1e-4
#: an accepted step lowering the cost by less than this fraction has converged
COST_TOLERANCE = 1e-9

_OFFSETS = (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5


@dataclass(frozen=True)
class PairFit:
    """centres_px (2, 2) (u, v) of the two discs; sigma_px (2,) their centroid sigma per
    image axis from the pixel noise (diagnostic); radius_px and blur_px the fitted disc
    radius and edge sigma."""

    centres_px: np.ndarray
    sigma_px: np.ndarray
    radius_px: float
    blur_px: float


def _problem(gray: np.ndarray, pixels: np.ndarray, centres0_px: np.ndarray, background: float):
    """The fit's sub-samples su, sv (n, S), pixel values (n,), start (9,) and box
    lower, upper (9,) for the blob of flat ``pixels`` in ``gray``."""
    h, w = gray.shape
    rows, cols = np.divmod(np.asarray(pixels), w)
    r0, r1 = max(rows.min() - MARGIN_PX, 0), min(rows.max() + MARGIN_PX, h - 1)
    c0, c1 = max(cols.min() - MARGIN_PX, 0), min(cols.max() + MARGIN_PX, w - 1)
    vv, uu = np.mgrid[r0 : r1 + 1, c0 : c1 + 1]
    values = gray[r0 : r1 + 1, c0 : c1 + 1].astype(float).ravel()
    du, dv = np.meshgrid(_OFFSETS, _OFFSETS)
    su = uu.ravel()[:, None] + du.ravel()[None, :]
    sv = vv.ravel()[:, None] + dv.ravel()[None, :]
    # start: each disc's area half the blob's, its light the blob's half above the level
    radius0 = max(np.sqrt(len(rows) / (2.0 * np.pi)), 0.8)
    peak = float(values.max() - background)
    start = np.array([*centres0_px[0], *centres0_px[1], peak, peak, radius0, 0.5, background])
    lower = np.array(
        [c0, r0, c0, r0, 0.0, 0.0, radius0 / RADIUS_FACTOR, BLUR_BOUNDS_PX[0], -np.inf]
    )
    upper = np.array(
        [c1, r1, c1, r1, np.inf, np.inf, radius0 * RADIUS_FACTOR, BLUR_BOUNDS_PX[1], np.inf]
    )
    start = np.clip(start, lower + 1e-9, upper - 1e-9)
    return su, sv, values, start, lower, upper


def _result(
    p: np.ndarray,
    normal: np.ndarray,
    cost: float,
    n_values: int,
    lower: np.ndarray,
    upper: np.ndarray,
) -> PairFit | None:
    """PairFit of the parameters p (9,) with J^T J ``normal`` (9, 9) and residual sum
    of squares ``cost`` over ``n_values`` pixels; None at a bound of the radius (not two
    discs of one size) or with a singular covariance."""
    if np.isclose(p[6], lower[6]) or np.isclose(p[6], upper[6]):
        return None
    var = cost / max(n_values - len(p), 1)
    try:
        cov = np.linalg.inv(normal) * var
    except np.linalg.LinAlgError:
        return None
    centres = np.array([[p[0], p[1]], [p[2], p[3]]])
    sigma = np.sqrt(np.array([0.5 * (cov[0, 0] + cov[1, 1]), 0.5 * (cov[2, 2] + cov[3, 3])]))
    if not np.all(np.isfinite(sigma)):
        return None
    return PairFit(centres, sigma, float(p[6]), float(p[7]))


def fit_pair(
    gray: np.ndarray,
    pixels: np.ndarray,
    centres0_px: np.ndarray,
    background: float,
    *,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> PairFit | None:
    """Fit two blurred discs to the blob of flat ``pixels`` (P,) in ``gray`` (H, W),
    starting from ``centres0_px`` (2, 2) (u, v; e.g. the 2-means halves' centroids) over
    the frame's ``background`` level, by the compiled Levenberg-Marquardt loop
    (``kernels.pair_fit.fit_pair_lm``; ``arithmetic``'s: the reference fits by SciPy's
    ``least_squares``). None when the fit does not converge or ends at a
    bound of the radius (not two discs of one size)."""
    su, sv, values, start, lower, upper = _problem(gray, pixels, centres0_px, background)
    p, normal, cost, converged = arithmetic.fit_pair_lm(
        su,
        sv,
        values,
        start,
        lower,
        upper,
        MAX_EVALUATIONS,
        CENTRE_TOLERANCE_PX,
        COST_TOLERANCE,
    )
    if not converged:
        return None
    return _result(p, normal, cost, len(values), lower, upper)
