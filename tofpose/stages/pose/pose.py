"""Pose from matched reflectors (§5): weighted SVD, line-of-sight refinement, covariance.

``y = R x + t`` (Eq. 5) maps target-frame catalog points x into the camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.stages.pose.kernels.pose import (
    MIN_LEAVE_ONE_OUT,
    absolute_orientation,
    leave_one_out_spread,
    ml_refine,
    range_bias_covariance,
    reflector_norms,
    residuals_jacobian,
)
from tofpose.stages.pose.kernels.pose import (
    covariance_envelope as kernel_covariance_envelope,
)
from tofpose.stages.pose.kernels.pose import (
    systematic_sigmas as kernel_systematic_sigmas,
)
from tofpose.stages.pose.kernels.pose import tangent_bases as bearing_tangent_bases
from tofpose.stages.pose.records import NO_RANGE_OFFSET, RangeOffset, Reflectors


def weighted_absolute_orientation(
    x_mm: np.ndarray, y_mm: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted absolute orientation (Eqs. 40-50): the paper's weighted SVD solution,
    computed by Horn's closed form (the unit quaternion that is the top eigenvector of a
    4 x 4 matrix built from Eq. 45's S; the same R to rounding, no LAPACK call).

    Minimises ``1/2 sum w_i ||y_i - (R x_i + t)||^2`` (Eq. 40): centroids (Eq. 41),
    S = sum w_i x~_i y~_i^T (Eq. 45), R = V diag(1, 1, det(V U^T)) U^T (Eq. 49, the
    reflection fix), t = y-bar - R x-bar (Eq. 50).

    Parameters
    ----------
    x_mm, y_mm : ndarray of shape (m, 3), m >= 3, not collinear.
    weights : ndarray of shape (m,), positive; None for equal weights.

    Returns
    -------
    R : ndarray (3, 3), t : ndarray (3,)
    """
    x = np.asarray(x_mm, float)
    y = np.asarray(y_mm, float)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"x and y must both be (m, 3), got {x.shape} and {y.shape}")
    if len(x) < 3:
        raise ValueError(f"a pose needs at least 3 point pairs, got {len(x)}")
    w = np.ones(len(x)) if weights is None else np.asarray(weights, float)
    if w.shape != (len(x),) or np.any(w <= 0) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be positive and finite, one per point")
    c = np.ascontiguousarray
    return absolute_orientation(c(x), c(y), c(w))


@dataclass
class RefinementResult:
    """R (3, 3), t (3,), per-iteration residuals (Eq. 52), iterations."""

    R: np.ndarray
    t: np.ndarray
    residuals: list[float]
    iterations: int


def refine_line_of_sight(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    R0: np.ndarray,
    t0: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    tol: float = 0.002,
    max_iterations: int = 200,
) -> RefinementResult:
    """Line-of-sight refinement (§5.2, Eqs. 51-52; Lu, Hager & Mjolsness 2000).

    Each iteration replaces the measurements by the predicted points projected on the
    measured lines of sight, ``y_i = [e_i^T (R x_i + t)] e_i`` (Eq. 51), re-solves the
    weighted SVD, and stops when the residual sum (Eq. 52) changes by less than ``tol``.
    The measured ranges enter only through the initial pose, so this converges to the
    bearing-only (PnP) solution.

    Parameters
    ----------
    x_mm : (m, 3) catalog points; bearings : (m, 3) unit lines of sight e_i.
    """
    R, t = R0, t0
    residuals: list[float] = []
    for it in range(1, max_iterations + 1):
        pred = x_mm @ R.T + t
        y = np.einsum("ij,ij->i", bearings, pred)[:, None] * bearings  # Eq. 51
        R, t = weighted_absolute_orientation(x_mm, y, weights)
        eps = float(np.linalg.norm(x_mm @ R.T + t - y, axis=1).sum())  # Eq. 52
        residuals.append(eps)
        if len(residuals) > 1 and abs(residuals[-1] - residuals[-2]) < tol:
            return RefinementResult(R, t, residuals, it)
    return RefinementResult(R, t, residuals, max_iterations)


def measurement_jacobian(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
    tangent_bases: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Whitened residuals r (3m,) and Jacobian J (3m, 6) of the ToF model (Eq. 10).

    Per reflector: two lateral residuals (predicted point off the measured line of sight,
    over range * sigma_bearing) and one range residual (e . (R x + t) - rho, over
    sigma_range). Parameters: small rotation (rad, left-multiplied) then translation (mm).
    tangent_bases : optional ``kernels.pose.tangent_bases(bearings)`` (m, 2, 3), which
    depends only on the measured bearings: an iteration passes it in instead of
    recomputing it.
    """
    refl = _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad)
    B = bearing_tangent_bases(refl.e) if tangent_bases is None else tangent_bases
    return residuals_jacobian(refl, _f64(R), _f64(t), B)


def _f64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad) -> Reflectors:
    """The matched reflectors as the kernels take them (a ``records.Reflectors``):
    catalog points and bearings (m, 3), ranges, range sigmas and bearing sigmas (m,),
    contiguous float64 (sigmas may be scalars)."""
    e = _f64(bearings)
    m = len(e)
    return Reflectors(
        x=_f64(x_mm),
        e=e,
        rho=_f64(ranges_mm),
        sr=_f64(np.broadcast_to(np.asarray(sigma_range_mm, float), (m,))),
        sb=_f64(np.broadcast_to(np.asarray(sigma_bearing_rad, float), (m,))),
    )


def reflector_whitened_norms(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
) -> np.ndarray:
    """Per reflector, the norm of its three whitened residuals (two lateral, one range)
    at the pose (R, t), shape (m,): how many predicted sigmas it sits off the fit."""
    r, _ = measurement_jacobian(x_mm, bearings, ranges_mm, R, t, sigma_range_mm, sigma_bearing_rad)
    return reflector_norms(r)


#: Gauss-Newton stops once a step moves the pose by less than 1e-4 of its 1-sigma: with
#: inconsistent data (large residuals) it converges only linearly and would otherwise
#: spend its whole iteration budget on steps far below any uncertainty
STEP_SIGMA2 = 1e-8


def systematic_sigmas(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
    max_range_mm: float = 200.0,
    max_bearing_rad: float = 1.0,
) -> tuple[float, float]:
    """The range (mm) and bearing (rad) errors this frame's reflectors show beyond their
    noise model, as two variance components.

    Real ToF ranges carry systematic errors (cyclic, amplitude-related, per pixel) of
    millimetres to centimetres that differ from reflector to reflector; small or blurred
    markers seen against a plate that is not black have centroids off by tenths of a
    pixel. A noise model fitted to shot noise then calls every reflector an outlier (or,
    worse, trusts a biased bearing). Each component is the smallest sigma_s >= 0 such that,
    with sigmas sqrt(sigma^2 + sigma_s^2), the median squared whitened residual of that
    kind (range: 1 degree of freedom per reflector; lateral: 2) equals the median of its
    chi^2: estimated from the frame itself, robust to a minority of true outliers (the
    median), capped at ``max_range_mm`` / ``max_bearing_rad``. Estimated apart, a range
    sigma does not grow to absorb bearing errors. Shapes: x_mm, bearings (m, 3);
    ranges, sigmas (m,). (0, 0) when the model already fits.
    """

    refl = _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad)
    er, eb = kernel_systematic_sigmas(
        refl, _f64(R), _f64(t), float(max_range_mm), float(max_bearing_rad)
    )
    return float(er), float(eb)


def common_range_bias_covariance(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
    bias_sigma_mm: float,
) -> np.ndarray:
    """(6, 6) pose covariance caused by a range offset common to every reflector, of
    sigma ``bias_sigma_mm``, that the frame cannot reveal (the fit absorbs it, mostly into
    the translation along the line of sight): s s^T sigma_b^2 with s = (J^T J)^-1 J^T g,
    g the whitened residuals' response to a unit offset (-1 / sigma_range on each range
    row). An uncalibrated camera's constant and drift errors are such an offset."""
    refl = _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad)
    return range_bias_covariance(refl, _f64(R), _f64(t), float(bias_sigma_mm))


@dataclass
class MLResult:
    """Maximum-likelihood pose with covariance.

    covariance : (6, 6) over (rotation vector rad, translation mm), left perturbation.
    chi2 : sum of squared whitened residuals; dof = 3 m - 6.
    reflector_norms : (m,) whitened residual norm of each reflector at the final pose
        (as ``reflector_whitened_norms``).
    bias_covariance : (6, 6) added by errors the data cannot reveal: a common range
        offset (``common_range_bias_covariance``) and the image scale's errors
        (``kernels.pose.class_scale_covariance``), or None.
    range_offset : the range offset common to the reflectors that the fit estimated and
        took out of their ranges (``kernels.pose.common_range_offset``), its posterior
        sigma and its prior's (a ``records.RangeOffset``; ``NO_RANGE_OFFSET``: none
        modelled).
    leave_one_out_covariance : (6, 6) spread of the poses fitted without one reflector
        each about this pose (``leave_one_out_covariance``), or None; the reported
        covariance is never narrower (``covariance_envelope``).
    """

    R: np.ndarray
    t: np.ndarray
    covariance: np.ndarray
    chi2: float
    iterations: int
    reflector_norms: np.ndarray
    bias_covariance: np.ndarray | None = None
    range_offset: RangeOffset = NO_RANGE_OFFSET
    leave_one_out_covariance: np.ndarray | None = None

    @property
    def range_offset_mm(self) -> float:
        return self.range_offset.mm


def refine_maximum_likelihood(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R0: np.ndarray,
    t0: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
    *,
    max_iterations: int = 10,
    tol: float = 1e-7,
) -> MLResult:
    """Gauss-Newton on bearings and ranges together (ours, beyond §5.2).

    The measurement model of Eq. 10, ``y~ = (rho + d_rho)(e + d_e)``, has independent
    range and line-of-sight errors. Minimising both whitened errors is the maximum-
    likelihood pose; unlike the pure line-of-sight iteration it keeps the ToF ranges,
    which dominate depth accuracy at long range. The covariance is (J^T J)^-1.
    """
    refl = _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad)
    R, t, cov, chi2, iterations, norms = ml_refine(
        refl, _f64(R0), _f64(t0), int(max_iterations), float(tol), STEP_SIGMA2
    )
    return MLResult(R, t, cov, float(chi2), int(iterations), norms)


def leave_one_out_covariance(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
) -> np.ndarray | None:
    """(6, 6) jackknife covariance of the ML pose (R, t) of m reflectors (ours): the
    spread ``(m - 1) / m sum_j d_j d_j^T`` of the poses fitted without reflector j
    about (R, t), each one Gauss-Newton step from (R, t)
    (``kernels.pose.leave_one_out_spread``), over (rotation vector rad, translation
    mm); None below ``MIN_LEAVE_ONE_OUT`` reflectors.

    Why: the model's covariance (J^T J)^-1 trusts every sigma. A reflector whose
    measurement is biased beyond its sigma (a marker partly hidden by something in
    front of it, a blurred blob pulled by its neighbour's halo) and that alone fixes
    some direction of the pose (the only large marker left, the far end of a lever)
    leaves no residual, so no chi^2 test sees it; the pose then errs by several of
    its sigmas. Leaving that reflector out moves the pose by about its error, and the
    spread says so. For consistent measurements it estimates the model's covariance.
    x_mm, bearings (m, 3); ranges_mm, sigma_range_mm, sigma_bearing_rad (m,)."""
    if len(x_mm) < MIN_LEAVE_ONE_OUT:
        return None
    refl = _reflectors(x_mm, bearings, ranges_mm, sigma_range_mm, sigma_bearing_rad)
    return leave_one_out_spread(refl, _f64(R), _f64(t))


def covariance_envelope(model: np.ndarray, other: np.ndarray | None) -> np.ndarray:
    """(6, 6): ``model`` widened to ``other`` in every direction where ``other`` is
    wider (``kernels.pose.covariance_envelope``: in the basis where ``model`` is the
    identity, the eigenvalues of ``other`` below 1 are raised to 1; the result contains
    both ellipsoids). ``model`` itself when ``other`` is None, and a copy of it when
    either is not finite or ``model`` is not positive definite."""
    if other is None:
        return model
    return kernel_covariance_envelope(_f64(model), _f64(other))
