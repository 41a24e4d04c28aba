"""§5 as stated: the weighted absolute orientation (Eqs. 40-50) by the SVD, the
line-of-sight refinement (Eqs. 51-52), and ours: the maximum-likelihood pose on the ToF
measurement model (Eq. 10) by SciPy's least squares, its covariance, the leave-one-out
spread and the covariance envelope.

The matched reflectors travel as one ``stages.pose.records.Reflectors`` (x (m, 3) catalog
points mm; e (m, 3) unit bearings; rho, sr (m,) mm; sb (m,) rad), a fit as a ``PoseFit``;
R (3, 3); t (3,) mm. A pose perturbation is (w, dt): R <- exp([w]x) R, t <- t + dt (the
rotation vector in the camera frame, rad; the covariance's order).
"""

from __future__ import annotations

import bisect

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from tofpose.stages.pose.constants import (
    MEDIAN_CHI2_1DOF,
    MEDIAN_CHI2_2DOF,
    MIN_LEAVE_ONE_OUT,
    REFINE_LOS,
    REFINE_ML,
)
from tofpose.stages.pose.records import (
    ConcludingCovariances,
    CovarianceTerms,
    OutlierFit,
    PoseFit,
    Reflectors,
)

#: a lateral sigma never below this, mm (a bearing sigma of 0 at any range)
MIN_LATERAL_SIGMA_MM = 1e-6


def absolute_orientation(x, y, w):
    """Eqs. 40-50: (R, t) minimising ``sum w_i |y_i - (R x_i + t)|^2``: weighted centroids
    (Eq. 41), S = sum w_i x~_i y~_i^T (Eq. 45), S = U Sigma V^T, R = V diag(1, 1,
    det(V U^T)) U^T (Eq. 49), t = y-bar - R x-bar (Eq. 50)."""
    x, y, w = np.asarray(x, float), np.asarray(y, float), np.asarray(w, float)
    xb = (w[:, None] * x).sum(axis=0) / w.sum()
    yb = (w[:, None] * y).sum(axis=0) / w.sum()
    S = ((x - xb) * w[:, None]).T @ (y - yb)
    U, _, Vt = np.linalg.svd(S)
    V = Vt.T
    R = V @ np.diag([1.0, 1.0, np.linalg.det(V @ U.T)]) @ U.T
    return R, yb - R @ xb


def tangent_basis(e) -> np.ndarray:
    """(m, 2, 3): an orthonormal basis of the plane normal to each bearing (the null
    space of e_i^T by the SVD; the residuals' norm does not depend on which)."""
    return np.array([np.linalg.svd(ei[None, :])[2][1:] for ei in np.asarray(e, float)])


def whitened_residuals(refl, R, t) -> np.ndarray:
    """(3m,): per reflector of ``refl`` (a ``Reflectors``: x, e, rho, sr, sb) the predicted
    point's two components across its line of sight over ``rho sigma_bearing`` (at least
    ``MIN_LATERAL_SIGMA_MM``), and its distance along it minus the measured range over
    ``sigma_range`` (Eq. 10: y~ = (rho + d_rho)(e + d_e))."""
    p = np.asarray(refl.x, float) @ R.T + t
    B = tangent_basis(refl.e)
    lateral = (
        np.einsum("mkj,mj->mk", B, p)
        / np.maximum(refl.rho * refl.sb, MIN_LATERAL_SIGMA_MM)[:, None]
    )
    along = (np.einsum("mj,mj->m", refl.e, p) - refl.rho) / refl.sr
    return np.column_stack((lateral, along)).ravel()


def _perturbed(R, t, params):
    return Rotation.from_rotvec(params[:3]).as_matrix() @ R, t + params[3:]


def jacobian(refl, R, t, step=1e-7) -> np.ndarray:
    """(3m, 6): the whitened residuals' derivative by (w, dt) at (R, t), by central
    differences (steps of ``step`` rad and ``step`` x 1000 mm)."""
    J = np.empty((3 * len(refl.x), 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = step if k < 3 else step * 1000.0
        plus = whitened_residuals(refl, *_perturbed(R, t, d))
        minus = whitened_residuals(refl, *_perturbed(R, t, -d))
        J[:, k] = (plus - minus) / (2.0 * d[k])
    return J


def ml_refine(refl, R0, t0):
    """The maximum-likelihood pose (ours, beyond §5.2): the (R, t) minimising the sum of
    squared ``whitened_residuals`` of the reflectors ``refl``, from (R0, t0), by SciPy's
    Levenberg-Marquardt. Returns R, t, covariance (6, 6) = (J^T J)^-1 at the optimum,
    chi^2."""

    R, t, _ = _ml_pose(refl, R0, t0)
    J = jacobian(refl, R, t)
    r = whitened_residuals(refl, R, t)
    return R, t, np.linalg.inv(J.T @ J), float((r**2).sum())


def _ml_pose(refl, R0, t0):
    """``ml_refine``'s optimum (R, t) from (R0, t0) and SciPy's count of residual
    evaluations."""

    def fun(params):
        return whitened_residuals(refl, *_perturbed(R0, t0, params))

    sol = least_squares(fun, np.zeros(6), method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    R, t = _perturbed(R0, t0, sol.x)
    return R, t, int(sol.nfev)


def leave_one_out_spread(refl, R, t) -> np.ndarray:
    """(6, 6), ours: ``(m - 1) / m sum_j d_j d_j^T``, d_j the Gauss-Newton step from (R, t)
    of the fit of the reflectors ``refl`` without reflector j, ``-(H - H_j)^-1 (g -
    g_j)`` with H = J^T J, g = J^T r and H_j, g_j reflector j's part; a j without which
    H - H_j is singular adds nothing; zeros below ``MIN_LEAVE_ONE_OUT`` reflectors."""
    m = len(refl.x)
    out = np.zeros((6, 6))
    if m < MIN_LEAVE_ONE_OUT:
        return out
    r = whitened_residuals(refl, R, t)
    J = jacobian(refl, R, t)
    for j in range(m):
        keep = np.ones(3 * m, bool)
        keep[3 * j : 3 * j + 3] = False
        H = J[keep].T @ J[keep]
        if np.linalg.eigvalsh(H).min() <= 0:
            continue
        d = -np.linalg.solve(H, J[keep].T @ r[keep])
        out += np.outer(d, d)
    return out * (m - 1) / m


def covariance_envelope(A, B) -> np.ndarray:
    """Ours: ``A`` widened to ``B`` where ``B`` is wider: with A = L L^T (Cholesky), the
    eigenvalues of L^-1 B L^-T below 1 raised to 1."""
    L = np.linalg.cholesky(A)
    Li = np.linalg.inv(L)
    w, V = np.linalg.eigh(Li @ B @ Li.T)
    return L @ (V * np.maximum(w, 1.0)) @ V.T @ L.T


def line_of_sight(x, e, R, t, w, tol, max_iterations):
    """§5.2, Eqs. 51-52: project each predicted point on its measured line of sight
    (Eq. 51), solve Eqs. 40-50 on those points, until the sum of the distances (Eq. 52)
    changes by less than ``tol``. Returns R, t, iterations."""
    prev = None
    for it in range(1, max_iterations + 1):
        p = np.asarray(x, float) @ R.T + t
        y = np.einsum("mj,mj->m", e, p)[:, None] * e  # Eq. 51
        R, t = absolute_orientation(x, y, w)
        eps = np.linalg.norm(np.asarray(x, float) @ R.T + t - y, axis=1).sum()  # Eq. 52
        if prev is not None and abs(eps - prev) < tol:
            return R, t, it
        prev = eps
    return R, t, max_iterations


# -- the fit as the pipeline runs it (tofpose.stages.pose.kernels.pose)
# ------------------------------
# Same names, arguments and returns (the records of stages.pose.records) as the kernels.
# ``fit`` is read by field name (core.records.FitSettings).

#: the line-of-sight iteration's cap in ``fit_pose``
LOS_MAX_ITERATIONS = 200
#: ``_excess_sigma``'s resolution: max_extra / 2^EXCESS_BITS
EXCESS_BITS = 16


def facing_cosine(R, t, centroid) -> float:
    """Cosine of the angle between the target's normal in the camera frame, R e_z, and
    the direction c = -(R centroid + t) from the target's centroid (3,) (catalog frame)
    to the camera: ``R[:, 2] . c / |c|``."""
    c = -(R @ np.asarray(centroid, float) + t)
    return float(R[:, 2] @ c / np.linalg.norm(c))


def reflector_norms(r) -> np.ndarray:
    """(m,): the norm of each reflector's three whitened residuals r (3m,)."""
    return np.linalg.norm(np.asarray(r, float).reshape(-1, 3), axis=1)


def _inverse_or_nan(H) -> np.ndarray:
    """H^-1, or NaN (n, n) when H is not positive definite (singular normal equations)."""
    try:
        np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return np.full(H.shape, np.nan)
    return np.linalg.inv(H)


def rows_of(refl, rows) -> Reflectors:
    """The reflectors ``refl`` of the rows ``rows`` (a bool mask or indices)."""
    return Reflectors(*(np.asarray(a)[rows] for a in refl))


def with_sigmas(refl, sr, sb) -> Reflectors:
    """The reflectors ``refl`` weighed with the sigmas sr (m,) mm and sb (m,) rad."""
    return Reflectors(x=refl.x, e=refl.e, rho=refl.rho, sr=sr, sb=sb)


def fit_pose(refl, fit) -> PoseFit:
    """One fit of the reflectors ``refl`` (a ``Reflectors``). Weights w = 1 / (sr^2 +
    (rho sb)^2) (Eq. 21), the weighted absolute orientation of their points y = rho e
    (Eq. 8; Eqs. 40-50), then the refinement ``fit.refinement``: ``REFINE_NONE`` none;
    ``REFINE_LOS`` the line of sight (Eqs. 51-52, tolerance ``fit.los_tolerance``, at
    most ``LOS_MAX_ITERATIONS``); ``REFINE_ML`` the maximum-likelihood pose from there
    (``ml_refine``'s optimum by SciPy; the kernel's Gauss-Newton stops where its step is
    below ``fit.step_sigma2`` squared sigmas, which this ignores: the two agree to the
    optimisers' tolerance, not bitwise). At the final pose, whatever the refinement: the
    covariance (J^T J)^-1 (6, 6) (NaN when singular), chi^2 = |r|^2 and the norms (m,)
    of the whitened residuals r (Eq. 10).

    Returns the ``PoseFit``: R (3, 3), t (3,), iterations (0; the LOS iterations; for ML
    SciPy's count of residual evaluations, not the kernel's Gauss-Newton steps),
    covariance, chi^2, norms (m,) and the sigmas given."""
    x, e, rho, sr, sb = refl
    w = 1.0 / (sr**2 + (rho * sb) ** 2)
    R, t = absolute_orientation(x, e * rho[:, None], w)
    iterations = 0
    if fit.refinement == REFINE_LOS:
        R, t, iterations = line_of_sight(x, e, R, t, w, fit.los_tolerance, LOS_MAX_ITERATIONS)
    elif fit.refinement == REFINE_ML:
        R, t, iterations = _ml_pose(refl, R, t)
    r = whitened_residuals(refl, R, t)
    J = jacobian(refl, R, t)
    return PoseFit(
        R=R,
        t=t,
        iterations=iterations,
        covariance=_inverse_or_nan(J.T @ J),
        chi2=float((r**2).sum()),
        norms=reflector_norms(r),
        sr=sr,
        sb=sb,
    )


def fit_without(j, refl, fit):
    """``fit_pose`` of every reflector but row j: the kept rows (m,) bool, R, t."""
    keep = np.arange(len(refl.x)) != j
    without = fit_pose(rows_of(refl, keep), fit)
    return keep, without.R, without.t


def _excess_sigma(z2, var, median_target, max_extra) -> float:
    """The smallest extra on the grid k max_extra / 2^16 (k = 0 .. 2^16) with
    ``median(z2 var / (var + extra^2)) <= median_target``; ``max_extra`` when none.
    z2 (m,): squared residuals whitened by sqrt(var) (m,). The median falls as extra
    grows, so a binary search over k finds it (the kernel's bisection finds the same
    grid point)."""
    n = 1 << EXCESS_BITS

    def extra(k):
        return max_extra * k / n

    def reached(k):
        return np.median(z2 * var / (var + extra(k) ** 2)) <= median_target

    return float(extra(min(bisect.bisect_left(range(n + 1), True, key=reached), n)))


def systematic_sigmas(refl, R, t, max_range_mm, max_bearing_rad):
    """The frame's excess range sigma (mm) and bearing sigma (rad) at the pose (R, t)
    (variance components, ours): with r the whitened residuals of the reflectors
    ``refl``, the smallest excess range sigma with which the median of the squared range
    residuals r_range^2 sr^2 / (sr^2 + extra^2) is at most the median of chi^2(1), and the
    smallest excess bearing sigma with which that of the lateral pairs |r_lat|^2 sb^2 /
    (sb^2 + extra^2) is at most the median of chi^2(2), each capped at ``max_range_mm`` /
    ``max_bearing_rad`` (``_excess_sigma``)."""
    r = whitened_residuals(refl, R, t).reshape(-1, 3)
    extra_range = _excess_sigma(r[:, 2] ** 2, refl.sr**2, MEDIAN_CHI2_1DOF, max_range_mm)
    lateral2 = r[:, 0] ** 2 + r[:, 1] ** 2
    extra_bearing = _excess_sigma(lateral2, refl.sb**2, MEDIAN_CHI2_2DOF, max_bearing_rad)
    return extra_range, extra_bearing


def fit_adaptive(refl, fit, max_bearing_rad) -> PoseFit:
    """``fit_pose`` with the noise model's sigmas ``refl.sr`` (mm), ``refl.sb`` (rad);
    then (``fit.adapt_range_sigma``, from 4 reflectors) the excess sigmas
    (``systematic_sigmas``, capped at ``fit.max_systematic_range_sigma_mm`` and
    ``max_bearing_rad``) at that fit, each the smallest over that fit and (when either is
    positive, from 5 reflectors) over every fit leaving one reflector out
    (``fit_without``); when either is positive, ``fit_pose`` again with sr = sqrt(sr^2 +
    extra_range^2), sb = sqrt(sb^2 + extra_bearing^2). (The kernel visits the
    leave-one-out fits worst-fitting first and stops when both reach 0: the same
    minimum.) Returns the ``PoseFit``, its sigmas the ones used."""
    first = fit_pose(refl, fit)
    m = len(refl.x)
    if not fit.adapt_range_sigma or m < 4:
        return first
    caps = (fit.max_systematic_range_sigma_mm, max_bearing_rad)
    er, eb = systematic_sigmas(refl, first.R, first.t, *caps)
    if (er > 0 or eb > 0) and m >= 5:
        for j in range(m):
            keep, Rj, tj = fit_without(j, refl, fit)
            er_j, eb_j = systematic_sigmas(rows_of(refl, keep), Rj, tj, *caps)
            er, eb = min(er, er_j), min(eb, eb_j)
    if er <= 0 and eb <= 0:
        return first
    sr, sb = np.sqrt(refl.sr**2 + er**2), np.sqrt(refl.sb**2 + eb**2)
    return fit_pose(with_sigmas(refl, sr, sb), fit)


def worst_outlier(refl, norms, fit) -> int:
    """The row to drop, -1 when the fit of the reflectors ``refl`` (whose whitened norms
    are ``norms`` (m,)) is consistent (ours). Below 5 reflectors: the largest norm when
    above ``fit.outlier_sigma``. From 5: nothing when the largest norm is at most
    ``fit.outlier_sigma`` and chi^2 = sum norms^2 is at most ``fit.outlier_chi2_per_dof``
    (3m - 6); else the reflector that the fit without it predicts worst in sigmas of
    that prediction (``deleted_residual_norm``), when that norm is above
    ``fit.outlier_sigma``."""
    m = len(norms)
    if m < 5:
        worst = int(np.argmax(norms))
        return worst if norms[worst] > fit.outlier_sigma else -1
    consistent = (norms**2).sum() <= fit.outlier_chi2_per_dof * (3 * m - 6)
    if norms.max() <= fit.outlier_sigma and consistent:
        return -1
    predicted = np.array([deleted_residual_norm(j, refl, fit) for j in range(m)])
    worst = int(np.argmax(predicted))
    return worst if predicted[worst] > fit.outlier_sigma else -1


def deleted_residual_norm(j, refl, fit) -> float:
    """sqrt(r^T S^-1 r), ours: r (3,) reflector j's whitened residuals at the pose fitted
    without it, S = I + J_j C J_j^T (3, 3), J_j (3, 6) their Jacobian there and C (6, 6)
    that fit's covariance (the deleted residual in sigmas of its prediction: the others predict a
    marker worst where it alone fixes the pose, and S counts that); 0 when C is
    singular."""
    keep = np.arange(len(refl.x)) != j
    without = fit_pose(rows_of(refl, keep), fit)
    C = without.covariance
    if not np.isfinite(C).all():
        return 0.0
    one = rows_of(refl, slice(j, j + 1))
    r = whitened_residuals(one, without.R, without.t)
    Jj = jacobian(one, without.R, without.t)
    S = np.eye(3) + Jj @ C @ Jj.T
    return float(np.sqrt(max(float(r @ np.linalg.solve(S, r)), 0.0)))


def mean_bearing(e) -> np.ndarray:
    """(3,): the unit vector along the sum of the bearings e (m, 3)."""
    s = np.asarray(e, float).sum(axis=0)
    return s / np.linalg.norm(s)


def pattern_scale_sigma(e, prior):
    """The image scale's prior sigma (relative) for bearings e (m, 3): the focal
    length's ``prior.focal_length_sigma_rel`` and a centroid bias common to the frame's
    markers ``prior.centroid_bias_rad`` over the pattern's rms angular radius r_rms =
    sqrt(mean(1 - (e_i . e_mean)^2)) (at least 1e-6), in quadrature. Returns (sigma,
    the unit mean bearing e_mean (3,))."""
    mean = mean_bearing(e)
    r_rms = np.sqrt(max(np.mean(1.0 - (e @ mean) ** 2), 1e-12))
    return float(np.hypot(prior.focal_length_sigma_rel, prior.centroid_bias_rad / r_rms)), mean


def scale_directions(e, B, mean) -> np.ndarray:
    """(m, 2): the tangent components in the bases B (m, 2, 3) of a unit image-scale
    error about the unit mean bearing ``mean`` (3,): a bearing scaled to
    e_i + kappa (e_i - mean (e_i . mean)) moves, to first order in kappa, by
    -kappa (e_i . mean) mean across its line of sight."""
    return -(e @ mean)[:, None] * np.einsum("mkj,j->mk", B, mean)


def _central_jacobian(fun, params, steps) -> np.ndarray:
    """d fun / d params by central differences of the given steps (one per parameter)."""
    cols = []
    for k, h in enumerate(steps):
        d = np.zeros(len(params))
        d[k] = h
        cols.append((fun(params + d) - fun(params - d)) / (2.0 * h))
    return np.column_stack(cols)


def common_range_offset(refl, R0, t0, prior):
    """The range offset b (mm) common to every reflector of ``refl`` (ranges read |p| +
    b), ours: the maximum a-posteriori (R, t, b, kappa) from (R0, t0, 0, 0), by SciPy's
    least squares on the whitened residuals (Eq. 10) of the ranges rho - b and of the
    bearings with an image scale error kappa (their lateral residuals plus kappa (rho_i -
    b) ``scale_directions`` / (rho_i - b) sb_i), and two prior residuals (b - mean_b) /
    sigma_b (``prior.mean_mm``, from which b starts) and
    kappa / sigma_kappa (``prior.sigma_mm``, ``pattern_scale_sigma``; kappa held at 0
    when sigma_kappa is 0). Returns b and its posterior sigma sqrt((J^T J)^-1_bb) (kappa
    marginalised) at the optimum, J by central differences; (mean_b, 0) when
    ``prior.sigma_mm`` <= 0, (mean_b, sigma_b) when J^T J is singular.

    The kernel takes 3 Gauss-Newton steps from the converged 6-parameter fit with a
    Jacobian that leaves out how the lateral sigmas (rho - b) sb move with b (a term of
    order |r_lateral|^2 / rho): the two agree to ~1e-2 of the posterior sigma."""
    if prior.sigma_mm <= 0:
        return float(prior.mean_mm), 0.0
    x, e, rho, sr, sb = refl
    sigma_kappa, mean = pattern_scale_sigma(e, prior)
    scale = scale_directions(e, tangent_basis(e), mean)
    fit_scale = sigma_kappa > 0

    def residuals(p):
        R, t = _perturbed(R0, t0, p[:6])
        b, kappa = p[6], (p[7] if fit_scale else 0.0)
        shifted = Reflectors(x=x, e=e, rho=rho - b, sr=sr, sb=sb)
        r = whitened_residuals(shifted, R, t).reshape(-1, 3)
        lat = np.maximum((rho - b) * sb, MIN_LATERAL_SIGMA_MM)
        r[:, :2] += kappa * ((rho - b) / lat)[:, None] * scale
        priors = [(b - prior.mean_mm) / prior.sigma_mm] + (
            [kappa / sigma_kappa] if fit_scale else []
        )
        return np.concatenate((r.ravel(), priors))

    n = 8 if fit_scale else 7
    start = np.zeros(n)
    start[6] = prior.mean_mm
    sol = least_squares(residuals, start, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    steps = np.array([1e-7, 1e-7, 1e-7, 1e-4, 1e-4, 1e-4, 1e-4, 1e-7])[:n]
    J = _central_jacobian(residuals, sol.x, steps)
    cov = _inverse_or_nan(J.T @ J)
    if not np.isfinite(cov).all():
        return float(prior.mean_mm), float(prior.sigma_mm)
    return float(sol.x[6]), float(np.sqrt(cov[6, 6]))


def fit_with_outliers(refl, fit, max_bearing_rad, offset_prior) -> OutlierFit:
    """The §5 fit with its outlier step and the common range offset (ours):
    ``fit_adaptive``; then (``fit.reject_outliers``) while more than ``fit.min_matches``
    reflectors remain and ``worst_outlier`` (with the sigmas that fit used) names one,
    drop it and fit the rest again; then (``offset_prior.sigma_mm`` > 0, ``REFINE_ML``, 4
    reflectors kept or more) the ``common_range_offset`` b of the kept reflectors at that
    fit, and when b != 0 the fit of the kept reflectors again with ranges rho - b.

    refl : the matched reflectors (a ``Reflectors``: x (m, 3), e (m, 3), rho (m,) and the
    noise model's sr (m,), sb (m,), mm / rad); fit : a ``FitSettings`` (read by field
    name); max_bearing_rad : the centroid cap, rad; offset_prior : a
    ``RangeOffsetPrior`` (sigma_mm, focal_length_sigma_rel, centroid_bias_rad). Returns
    the ``OutlierFit``: kept (m,) bool, the ``PoseFit`` of the kept reflectors, b (mm, 0
    when not estimated) and its posterior sigma (the prior's when not estimated)."""
    rows = np.arange(len(refl.x))
    result = fit_adaptive(refl, fit, max_bearing_rad)
    while fit.reject_outliers and len(rows) > fit.min_matches:
        kept_now = with_sigmas(rows_of(refl, rows), result.sr, result.sb)
        worst = worst_outlier(kept_now, result.norms, fit)
        if worst < 0:
            break
        rows = np.delete(rows, worst)
        result = fit_adaptive(rows_of(refl, rows), fit, max_bearing_rad)
    # not estimated: the prior's mean (0 unless one was learned) and sigma
    offset, offset_sigma = float(offset_prior.mean_mm), offset_prior.sigma_mm
    if offset_prior.sigma_mm > 0 and fit.refinement == REFINE_ML and len(rows) >= 4:
        used = with_sigmas(rows_of(refl, rows), result.sr, result.sb)
        offset, offset_sigma = common_range_offset(used, result.R, result.t, offset_prior)
    if offset != 0.0:
        x, e, rho, sr, sb = rows_of(refl, rows)
        shifted = Reflectors(x=x, e=e, rho=rho - offset, sr=sr, sb=sb)
        result = fit_adaptive(shifted, fit, max_bearing_rad)
    kept = np.zeros(len(refl.x), bool)
    kept[rows] = True
    return OutlierFit(kept=kept, fit=result, offset_mm=offset, offset_sigma_mm=offset_sigma)


def _pose_response(J, g) -> np.ndarray:
    """s = (J^T J)^-1 J^T g (6,): the pose's least-squares response to residuals g."""
    return np.linalg.solve(J.T @ J, J.T @ g)


def range_bias_covariance(refl, R, t, bias_sigma_mm) -> np.ndarray:
    """(6, 6), ours: the pose covariance from a range offset common to every reflector of
    ``refl``, of sigma ``bias_sigma_mm``: sigma^2 s s^T, s = (J^T J)^-1 J^T g with g (3m,)
    the whitened residuals' response to a unit offset (-1 / sr on the range rows, 0 on
    the lateral ones). NaN when J^T J is singular."""
    J = jacobian(refl, R, t)
    if not np.isfinite(_inverse_or_nan(J.T @ J)).all():
        return np.full((6, 6), np.nan)
    g = np.zeros(3 * len(refl.x))
    g[2::3] = -1.0 / refl.sr
    s = _pose_response(J, g)
    return bias_sigma_mm**2 * np.outer(s, s)


def class_scale_covariance(refl, R, t, group, n_groups, bias_rad, common_scale_sigma) -> np.ndarray:
    """(6, 6), ours: the pose covariance from image-scale errors of the reflectors
    ``refl`` (bearings scaled about the mean bearing by 1 + kappa, as in
    ``common_range_offset``): one common scale of sigma ``common_scale_sigma``, and one
    per group g in [0, n_groups) of reflectors (``group`` (m,)), independent, of sigma
    ``bias_rad / r_g`` (r_g the group's rms angle from the mean bearing of all, at least
    1e-6). Each adds sigma^2 s s^T, s = (J^T J)^-1 J^T g, g (3m,) the whitened lateral
    residuals' response to a unit kappa of its reflectors (``scale_directions`` rho /
    (rho sb)); groups without reflectors or with sigma 0 add nothing. NaN when J^T J is
    singular."""
    J = jacobian(refl, R, t)
    if not np.isfinite(_inverse_or_nan(J.T @ J)).all():
        return np.full((6, 6), np.nan)
    e, rho, sb = refl.e, refl.rho, refl.sb
    m = len(refl.x)
    mean = mean_bearing(e)
    lat = np.maximum(rho * sb, MIN_LATERAL_SIGMA_MM)
    response = scale_directions(e, tangent_basis(e), mean) * (rho / lat)[:, None]
    r2 = 1.0 - (e @ mean) ** 2
    members = [np.ones(m, bool)] + [np.asarray(group) == k for k in range(n_groups)]
    out = np.zeros((6, 6))
    for k, member in enumerate(members):
        if not member.any():
            continue
        r_g = np.sqrt(max(r2[member].mean(), 1e-12))
        sigma = common_scale_sigma if k == 0 else bias_rad / r_g
        if sigma <= 0:
            continue
        g = np.zeros((m, 3))
        g[member, :2] = response[member]
        s = _pose_response(J, g.ravel())
        out += sigma**2 * np.outer(s, s)
    return out


def point_residuals_mm(x, y, R, t):
    """|y_i - (R x_i + t)| (m,) mm of matched points x (m, 3) (target frame) and y (m, 3)
    (camera frame), and their RMS."""
    d = np.linalg.norm(np.asarray(y, float) - (np.asarray(x, float) @ R.T + t), axis=1)
    return d, float(np.sqrt(np.mean(d**2)))


def concluding_covariances(refl, R, t, terms: CovarianceTerms) -> ConcludingCovariances:
    """The covariances a concluded fit reports beside the model's (ours):
    ``range_bias_covariance`` when ``terms.bias_sigma_mm`` > 0, ``class_scale_covariance``
    when ``terms.by_size`` and ``leave_one_out_spread`` when ``terms.leave_one_out`` (and
    at least ``MIN_LEAVE_ONE_OUT`` reflectors), each (6, 6), zeros where off."""
    zeros = np.zeros((6, 6))
    return ConcludingCovariances(
        range_bias=(
            range_bias_covariance(refl, R, t, terms.bias_sigma_mm)
            if terms.bias_sigma_mm > 0
            else zeros
        ),
        by_size=(
            class_scale_covariance(
                refl, R, t, terms.group, terms.n_groups, terms.bias_rad, terms.common_scale_sigma
            )
            if terms.by_size
            else zeros
        ),
        spread=(
            leave_one_out_spread(refl, R, t)
            if terms.leave_one_out and len(refl.x) >= MIN_LEAVE_ONE_OUT
            else zeros
        ),
    )
