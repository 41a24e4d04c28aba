"""The records of §5 as the compiled fit and its reference statement take and return them
(``kernels.pose``, ``kernels.solve`` and ``reference.pose``, ``reference.solve``): the
matched reflectors, a fit, the fit with its outlier step, the pose of matched pairs, and
the prior of the common range offset. ``typing.NamedTuple``s: numba compiles them as
tuples with named fields; each is built by keyword.

Shapes: m matched reflectors; x, e (m, 3); rho, sr, sb (m,); R (3, 3); t (3,).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Reflectors(NamedTuple):
    """m matched reflectors as the fit reads them, row i one reflector: ``x`` (m, 3) mm
    catalog points (target frame), ``e`` (m, 3) unit bearings (Eq. 9), ``rho`` (m,) mm
    ranges, and the sigmas the fit weighs them with, ``sr`` (m,) mm (range) and ``sb``
    (m,) rad (bearing). Their points are ``y = rho e`` (Eq. 8)."""

    x: np.ndarray
    e: np.ndarray
    rho: np.ndarray
    sr: np.ndarray
    sb: np.ndarray


class PoseFit(NamedTuple):
    """One fit of m reflectors (``fit_pose``, ``fit_adaptive``): the pose ``R`` (3, 3),
    ``t`` (3,) mm, its refinement's ``iterations``, the ``covariance`` (6, 6) (J^T J)^-1
    at the pose (rotation vector rad, translation mm; NaN when singular), ``chi2`` and
    the whitened residual ``norms`` (m,) there, and the sigmas the fit used, ``sr`` (m,)
    mm and ``sb`` (m,) rad (the frame's excess components included)."""

    R: np.ndarray
    t: np.ndarray
    iterations: int
    covariance: np.ndarray
    chi2: float
    norms: np.ndarray
    sr: np.ndarray
    sb: np.ndarray


class OutlierFit(NamedTuple):
    """The fit with its outlier step and the common range offset
    (``fit_with_outliers``): ``kept`` (m,) bool, the reflectors the final ``fit`` (a
    ``PoseFit`` of the kept ones) is of, the range offset ``offset_mm`` common to them
    (0 when not estimated; taken out of their ranges before the final fit) and its
    posterior sigma ``offset_sigma_mm`` (the prior's when not estimated)."""

    kept: np.ndarray
    fit: PoseFit
    offset_mm: float
    offset_sigma_mm: float


class RangeOffset(NamedTuple):
    """A frame's range offset common to its reflectors, as the fit saw it: ``mm`` the
    posterior mean taken out of the ranges (the prior's mean when not estimated),
    ``sigma_mm`` its posterior sigma (the prior's when not estimated),
    ``prior_sigma_mm`` the prior's sigma (0: no offset modelled) and ``prior_mean_mm``
    its mean."""

    mm: float
    sigma_mm: float
    prior_sigma_mm: float
    prior_mean_mm: float = 0.0

    def likelihood(self) -> tuple[float, float] | None:
        """(mean, variance) mm, mm^2: what the frame alone says of the offset, the prior
        divided out of the posterior (Gaussians: ``1 / v = 1 / sigma^2 - 1 / prior^2``,
        ``mean = v (mm / sigma^2 - prior_mean / prior^2)``); None when the frame says
        nothing the prior did not (its posterior is no narrower than the prior, or no
        offset was modelled)."""
        if not (self.prior_sigma_mm > 0 and self.sigma_mm > 0):
            return None
        precision = 1.0 / self.sigma_mm**2 - 1.0 / self.prior_sigma_mm**2
        if not precision > 1e-12 / self.prior_sigma_mm**2:
            return None
        v = 1.0 / precision
        return v * (self.mm / self.sigma_mm**2 - self.prior_mean_mm / self.prior_sigma_mm**2), v


#: no offset modelled
NO_RANGE_OFFSET = RangeOffset(0.0, 0.0, 0.0)


class SolvedPairs(NamedTuple):
    """The pose of matched pairs (``solve_pairs``): ``k_idx``, ``i_idx`` (m,) int64 the
    (candidate, catalog) pairs after completion, ``uv`` (m, 2) px their centroids after
    the perspective-bias correction, ``observed`` the matched reflectors as measured (a
    ``Reflectors``: the unmixed ranges and their sigmas, the noise model's bearing sigmas;
    the offset not taken out), and ``result`` the fit with its outlier step (an
    ``OutlierFit``)."""

    k_idx: np.ndarray
    i_idx: np.ndarray
    uv: np.ndarray
    observed: Reflectors
    result: OutlierFit


class RangeOffsetPrior(NamedTuple):
    """What is known of the common range offset before a frame (``common_range_offset``).

    sigma_mm : prior sigma of the offset (0: not estimated); focal_length_sigma_rel :
    relative sigma of the focal length's calibration (the image scale;
    ``PipelineConfig.focal_length_sigma_rel``); centroid_bias_rad : a systematic centroid
    error common to the frame's markers (rad: ``common_centroid_bias_px`` times
    ``solve.centroid_bias_factor`` over fx), which
    scales the pattern by ``centroid_bias_rad / r_rms`` (r_rms its rms angular radius);
    mean_mm : the prior's mean (0: none known; a mean learned over a recording,
    ``stages.pose.range_bias``), taken out of the ranges when the offset is not
    estimated."""

    sigma_mm: float
    focal_length_sigma_rel: float
    centroid_bias_rad: float
    mean_mm: float = 0.0


#: no offset estimated
NO_OFFSET = RangeOffsetPrior(sigma_mm=0.0, focal_length_sigma_rel=0.0, centroid_bias_rad=0.0)


class CovarianceTerms(NamedTuple):
    """Which covariances a concluded fit reports beside the model's
    (``concluding_covariances``), with their sigmas: ``bias_sigma_mm`` of the range
    offset common to the reflectors (0: none); ``by_size`` whether the image scale's
    errors enter, one common of relative sigma ``common_scale_sigma`` (the focal
    length's and the markers' common centroid error over the pattern's rms radius,
    ``kernels.pose.pattern_scale_sigma``) and one per size class from ``bias_rad``
    (the per-class centroid error, rad; ``group`` (m,) int64 each
    reflector's class in [0, ``n_groups``)); ``leave_one_out`` whether the jackknife
    spread is computed."""

    bias_sigma_mm: float
    by_size: bool
    group: np.ndarray
    n_groups: int
    bias_rad: float
    common_scale_sigma: float
    leave_one_out: bool


class ConcludingCovariances(NamedTuple):
    """The (6, 6) covariances of ``concluding_covariances`` over (rotation vector rad,
    translation mm): ``range_bias`` (of the common range offset), ``by_size`` (of the
    image scale's errors) and ``spread`` (the leave-one-out spread); zeros where the
    term is off."""

    range_bias: np.ndarray
    by_size: np.ndarray
    spread: np.ndarray
