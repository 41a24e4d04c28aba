"""Pose from matched reflectors (§5): weighted SVD, line-of-sight refinement, covariance.

``y = R x + t`` (Eq. 5) maps target-frame catalog points x into the camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.geometry import skew
from tofpose.robust import median_1d


def weighted_svd(
    x_mm: np.ndarray, y_mm: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted absolute orientation (Eqs. 40-50).

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
    ws = w / w.sum()
    x_bar, y_bar = ws @ x, ws @ y  # Eq. 41
    xc, yc = x - x_bar, y - y_bar  # Eq. 42
    S = (xc * w[:, None]).T @ yc  # Eq. 45
    U, _, Vt = np.linalg.svd(S)
    V = Vt.T
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(V @ U.T)) or 1.0])
    R = V @ D @ U.T  # Eq. 49
    t = y_bar - R @ x_bar  # Eq. 50
    return R, t


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
        R, t = weighted_svd(x_mm, y, weights)
        eps = float(np.linalg.norm(x_mm @ R.T + t - y, axis=1).sum())  # Eq. 52
        residuals.append(eps)
        if len(residuals) > 1 and abs(residuals[-1] - residuals[-2]) < tol:
            return RefinementResult(R, t, residuals, it)
    return RefinementResult(R, t, residuals, max_iterations)


def _tangent_bases(bearings: np.ndarray) -> np.ndarray:
    """Two unit vectors orthogonal to each bearing, shape (m, 2, 3)."""
    ref = np.where(np.abs(bearings[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a = _cross(bearings, ref)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = _cross(bearings, a)
    return np.stack((a, b), axis=1)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (m, 3) arrays: ``np.cross``'s arithmetic without its
    per-call axis handling (which costs more than the product for a few rows)."""
    out = np.empty_like(u)
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


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
    tangent_bases : optional ``_tangent_bases(bearings)`` (m, 2, 3), which depends only on
    the measured bearings: an iteration passes it in instead of recomputing it.
    """
    rx = x_mm @ R.T
    pred = rx + t
    B = _tangent_bases(bearings) if tangent_bases is None else tangent_bases  # (m, 2, 3)
    lat_sigma = np.maximum(ranges_mm * sigma_bearing_rad, 1e-6)
    r_lat = np.einsum("mkj,mj->mk", B, pred) / lat_sigma[:, None]
    r_rng = (np.einsum("mj,mj->m", bearings, pred) - ranges_mm) / sigma_range_mm
    m = len(rx)
    dP = np.zeros((m, 3, 6))
    # d(R x + t) / d(rotation vector) = -[R x]_x ; / d t = I
    dP[:, 0, 1], dP[:, 0, 2] = rx[:, 2], -rx[:, 1]
    dP[:, 1, 0], dP[:, 1, 2] = -rx[:, 2], rx[:, 0]
    dP[:, 2, 0], dP[:, 2, 1] = rx[:, 1], -rx[:, 0]
    dP[:, 0, 3] = dP[:, 1, 4] = dP[:, 2, 5] = 1.0  # (m, 3, 6)
    J_lat = np.einsum("mkj,mjp->mkp", B, dP) / lat_sigma[:, None, None]
    J_rng = np.einsum("mj,mjp->mp", bearings, dP) / sigma_range_mm[:, None]
    r = np.concatenate((r_lat, r_rng[:, None]), axis=1).reshape(-1)
    J = np.concatenate((J_lat, J_rng[:, None, :]), axis=1).reshape(-1, 6)
    return r, J


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
    return np.linalg.norm(r.reshape(-1, 3), axis=1)


#: Gauss-Newton stops once a step moves the pose by less than 1e-4 of its 1-sigma: with
#: inconsistent data (large residuals) it converges only linearly and would otherwise
#: spend its whole iteration budget on steps far below any uncertainty
STEP_SIGMA2 = 1e-8

MEDIAN_CHI2_3DOF = 2.366  # median of a chi-square with 3 degrees of freedom


def systematic_range_sigma_mm(
    x_mm: np.ndarray,
    bearings: np.ndarray,
    ranges_mm: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    sigma_range_mm: np.ndarray,
    sigma_bearing_rad: np.ndarray,
    max_mm: float = 200.0,
) -> float:
    """The range error common to this frame's reflectors that their noise model lacks.

    Real ToF ranges carry systematic errors (cyclic, amplitude-related, per pixel) of
    millimetres to centimetres that differ from reflector to reflector; a noise model
    fitted to shot noise then calls every reflector an outlier. This returns the smallest
    sigma_s >= 0 such that, with range sigmas sqrt(sigma_range^2 + sigma_s^2), the median
    squared whitened residual equals the median of chi^2(3): a variance component
    estimated from the frame itself, robust to a minority of true outliers (the median).
    Shapes: x_mm, bearings (m, 3); ranges, sigmas (m,). 0 when the model already fits.
    """

    # At a fixed pose only the range sigma changes with sigma_s: the whitened lateral
    # residuals and the raw range residuals (unit range sigma) are computed once.
    r, _ = measurement_jacobian(x_mm, bearings, ranges_mm, R, t, np.ones(len(x_mm)),
                                sigma_bearing_rad)  # fmt: skip
    r = r.reshape(-1, 3)
    lat2 = (r[:, :2] ** 2).sum(axis=1)
    rng2 = r[:, 2] ** 2
    var_range = np.asarray(sigma_range_mm, float) ** 2

    def median_z2(extra: float) -> float:
        return median_1d(lat2 + rng2 / (var_range + extra**2))

    if median_z2(0.0) <= MEDIAN_CHI2_3DOF:
        return 0.0
    if median_z2(max_mm) > MEDIAN_CHI2_3DOF:
        return max_mm
    lo, hi = 0.0, max_mm
    for _ in range(16):  # bisection to max_mm / 2^16 (3 um at the default cap)
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if median_z2(mid) > MEDIAN_CHI2_3DOF else (lo, mid)
    return hi


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
    _, J = measurement_jacobian(x_mm, bearings, ranges_mm, R, t, sigma_range_mm,
                                sigma_bearing_rad)  # fmt: skip
    g = np.zeros(J.shape[0])
    g[2::3] = -1.0 / np.asarray(sigma_range_mm, float)
    s = np.linalg.solve(J.T @ J, J.T @ g)
    return bias_sigma_mm**2 * np.outer(s, s)


@dataclass
class MLResult:
    """Maximum-likelihood pose with covariance.

    covariance : (6, 6) over (rotation vector rad, translation mm), left perturbation.
    chi2 : sum of squared whitened residuals; dof = 3 m - 6.
    reflector_norms : (m,) whitened residual norm of each reflector at the final pose
        (as ``reflector_whitened_norms``).
    bias_covariance : (6, 6) added by a common range offset the data cannot reveal
        (``common_range_bias_covariance``), or None.
    """

    R: np.ndarray
    t: np.ndarray
    covariance: np.ndarray
    chi2: float
    iterations: int
    reflector_norms: np.ndarray
    bias_covariance: np.ndarray | None = None


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
    R, t = R0.copy(), t0.copy()
    iterations = 0
    B = _tangent_bases(bearings)
    for iterations in range(1, max_iterations + 1):  # noqa: B007
        r, J = measurement_jacobian(
            x_mm, bearings, ranges_mm, R, t, sigma_range_mm, sigma_bearing_rad, B
        )
        H = J.T @ J
        try:
            delta = -np.linalg.solve(H, J.T @ r)
        except np.linalg.LinAlgError:
            break
        w = delta[:3]
        angle = np.linalg.norm(w)
        if angle > 0:
            k = w / angle
            Kx = skew(k)
            dR = np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx
            R = dR @ R
        t = t + delta[3:]
        # converged when the step is below tol in mm/rad, or a negligible fraction of the
        # pose's own uncertainty (delta^T H delta is the step in sigmas, squared)
        if np.linalg.norm(delta) < tol or float(delta @ H @ delta) < STEP_SIGMA2:
            break
    r, J = measurement_jacobian(
        x_mm, bearings, ranges_mm, R, t, sigma_range_mm, sigma_bearing_rad, B
    )
    try:
        cov = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.nan)
    return MLResult(R, t, cov, float(r @ r), iterations, np.linalg.norm(r.reshape(-1, 3), axis=1))
