"""Pose from matched reflectors (§5), compiled: weighted SVD (Eqs. 40-50), the whitened
residuals and Jacobian of the ToF measurement model (Eq. 10), Gauss-Newton maximum-
likelihood refinement with its covariance, and the frame's excess range and bearing
sigmas (variance components).

The readable specification, input checks and docstrings are in ``tofpose.stages.pose.pose``,
whose functions call these. The matched reflectors travel as one ``records.Reflectors``
(x, e (m, 3); rho, sr, sb (m,)), a fit as a ``records.PoseFit``; R (3, 3); t (3,).
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.small_matrices import (
    cholesky,
    cholesky_inverse,
    cholesky_solve,
    gram,
    lower_solve,
    matmul3,
    rotation_from_correlation,
    symmetric_eigen,
    transposed_times,
)
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.pose.constants import (
    MEDIAN_CHI2_1DOF,
    MEDIAN_CHI2_2DOF,
    MIN_LEAVE_ONE_OUT,
    REFINE_LOS,
    REFINE_ML,
)
from tofpose.stages.pose.records import ConcludingCovariances, OutlierFit, PoseFit, Reflectors


@jit
def absolute_orientation(x, y, w):
    """Weighted absolute orientation: R (3, 3), t (3,) minimising
    ``sum w_i ||y_i - (R x_i + t)||^2`` (Eqs. 40-50). The rotation of Eqs. 45-49 by
    Horn's closed form (``small_matrices.rotation_from_correlation``: the same R as the
    SVD's, without LAPACK)."""
    m = x.shape[0]
    w_sum = 0.0
    for i in range(m):
        w_sum += w[i]
    x_bar = np.zeros(3)  # Eq. 41
    y_bar = np.zeros(3)
    for i in range(m):
        ws = w[i] / w_sum
        for a in range(3):
            x_bar[a] += ws * x[i, a]
            y_bar[a] += ws * y[i, a]
    S = np.zeros((3, 3))  # Eq. 45, over the centred points (Eq. 42)
    for i in range(m):
        for a in range(3):
            xa = w[i] * (x[i, a] - x_bar[a])
            for b in range(3):
                S[a, b] += xa * (y[i, b] - y_bar[b])
    R = rotation_from_correlation(S)  # Eqs. 46-49
    t = np.empty(3)  # Eq. 50
    for a in range(3):
        t[a] = y_bar[a] - (R[a, 0] * x_bar[0] + R[a, 1] * x_bar[1] + R[a, 2] * x_bar[2])
    return R, t


@jit
def facing_cosine(R, t, centroid):
    """Cosine between the target normal R e_z and the direction from the target's
    centroid (3,) (catalog frame) to the camera, for the pose (R (3, 3), t (3,))."""
    mx, my, mz = centroid[0], centroid[1], centroid[2]
    cx = -(R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz + t[0])
    cy = -(R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz + t[1])
    cz = -(R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz + t[2])
    return (R[0, 2] * cx + R[1, 2] * cy + R[2, 2] * cz) / np.sqrt(cx * cx + cy * cy + cz * cz)


@jit
def tangent_bases(e):
    """Two unit vectors orthogonal to each bearing, (m, 2, 3)."""
    m = e.shape[0]
    out = np.empty((m, 2, 3))
    for i in range(m):
        if abs(e[i, 0]) < 0.9:
            r0, r1, r2 = 1.0, 0.0, 0.0
        else:
            r0, r1, r2 = 0.0, 1.0, 0.0
        a0 = e[i, 1] * r2 - e[i, 2] * r1
        a1 = e[i, 2] * r0 - e[i, 0] * r2
        a2 = e[i, 0] * r1 - e[i, 1] * r0
        n = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        a0, a1, a2 = a0 / n, a1 / n, a2 / n
        out[i, 0, 0], out[i, 0, 1], out[i, 0, 2] = a0, a1, a2
        out[i, 1, 0] = e[i, 1] * a2 - e[i, 2] * a1
        out[i, 1, 1] = e[i, 2] * a0 - e[i, 0] * a2
        out[i, 1, 2] = e[i, 0] * a1 - e[i, 1] * a0
    return out


@jit
def residuals_jacobian(refl, R, t, B):
    """Whitened residuals r (3m,) and Jacobian J (3m, 6) of the ToF model (Eq. 10) of the
    reflectors ``refl`` (a ``records.Reflectors``) at the pose (R, t): per reflector two
    lateral residuals (over range * sigma_bearing) and one range residual (over
    sigma_range); parameters: small left rotation (rad) then translation (mm).
    B : ``tangent_bases(refl.e)``."""
    x, e, rho, sr, sb = refl.x, refl.e, refl.rho, refl.sr, refl.sb
    m = x.shape[0]
    r = np.empty(3 * m)
    J = np.zeros((3 * m, 6))
    for i in range(m):
        rx0 = R[0, 0] * x[i, 0] + R[0, 1] * x[i, 1] + R[0, 2] * x[i, 2]
        rx1 = R[1, 0] * x[i, 0] + R[1, 1] * x[i, 1] + R[1, 2] * x[i, 2]
        rx2 = R[2, 0] * x[i, 0] + R[2, 1] * x[i, 1] + R[2, 2] * x[i, 2]
        p0, p1, p2 = rx0 + t[0], rx1 + t[1], rx2 + t[2]
        lat = max(rho[i] * sb[i], 1e-6)
        # d(R x + t) / d(w, t) = [-[R x]_x | I]; each residual's row is its direction b
        # (a tangent or the bearing) times that, over its sigma: (R x) x b for the
        # rotation, b for the translation (scalars: no array per reflector)
        for k in range(3):
            if k < 2:
                b0, b1, b2 = B[i, k, 0], B[i, k, 1], B[i, k, 2]
                r[3 * i + k] = (b0 * p0 + b1 * p1 + b2 * p2) / lat
                scale = lat
            else:
                b0, b1, b2 = e[i, 0], e[i, 1], e[i, 2]
                r[3 * i + 2] = ((b0 * p0 + b1 * p1 + b2 * p2) - rho[i]) / sr[i]
                scale = sr[i]
            row = 3 * i + k
            J[row, 0] = (b1 * -rx2 + b2 * rx1) / scale
            J[row, 1] = (b0 * rx2 + b2 * -rx0) / scale
            J[row, 2] = (b0 * -rx1 + b1 * rx0) / scale
            J[row, 3] = b0 / scale
            J[row, 4] = b1 / scale
            J[row, 5] = b2 / scale
    return r, J


@jit
def reflector_norms(r):
    """Norm of each reflector's three whitened residuals: r (3m,) -> (m,)."""
    m = r.shape[0] // 3
    out = np.empty(m)
    for i in range(m):
        out[i] = np.sqrt(r[3 * i] ** 2 + r[3 * i + 1] ** 2 + r[3 * i + 2] ** 2)
    return out


@jit
def rotation_step(w):
    """exp([w]_x) by Rodrigues' formula, w (3,) rad -> (3, 3)."""
    angle = np.sqrt(w[0] ** 2 + w[1] ** 2 + w[2] ** 2)
    if angle == 0:
        return np.eye(3)
    k0, k1, k2 = w[0] / angle, w[1] / angle, w[2] / angle
    K = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * matmul3(K, K)


@jit
def ml_refine(refl, R0, t0, max_iterations, tol, step_sigma2):
    """Gauss-Newton on bearings and ranges together (ours, beyond §5.2) from (R0, t0), of
    the reflectors ``refl`` (a ``records.Reflectors``).

    Stops when a step is below ``tol`` (mm / rad) or below ``step_sigma2`` in squared
    sigmas of the pose. Returns R, t, covariance (6, 6) = (J^T J)^-1 at the final pose
    (NaN when singular), chi^2, iterations, per-reflector whitened norms (m,).
    """
    R, t = R0.copy(), t0.copy()
    B = tangent_bases(refl.e)
    iterations = 0
    for it in range(1, max_iterations + 1):
        iterations = it
        r, J = residuals_jacobian(refl, R, t, B)
        H = gram(J)
        L, ok = cholesky(H)
        if not ok:  # singular normal equations
            break
        delta = -cholesky_solve(L, transposed_times(J, r))
        R = matmul3(rotation_step(delta[:3]), R)
        t = t + delta[3:]
        step2 = 0.0  # delta^T H delta
        for a in range(6):
            for b in range(6):
                step2 += delta[a] * H[a, b] * delta[b]
        if np.sqrt((delta**2).sum()) < tol or step2 < step_sigma2:
            break
    r, J = residuals_jacobian(refl, R, t, B)
    L, ok = cholesky(gram(J))
    cov = cholesky_inverse(L) if ok else np.full((6, 6), np.nan)
    return R, t, cov, (r**2).sum(), iterations, reflector_norms(r)


@jit
def leave_one_out_spread(refl, R, t):
    """(6, 6) spread of the leave-one-out poses about the pose (R, t) of all m
    reflectors ``refl`` (a ``records.Reflectors``): ``(m - 1) / m sum_j d_j d_j^T``
    (ours: the jackknife estimate of the pose's error covariance, beside the model's
    (J^T J)^-1), with d_j the Gauss-Newton step from (R, t) of the fit without reflector
    j, ``-(H - H_j)^-1 (J^T r - J_j^T r_j)`` (H = J^T J; J_j, r_j reflector j's three
    rows), over (rotation vector rad, translation mm) with the covariance's left
    perturbation. One step from the full optimum is the refit to second order in the
    step. A biased reflector that the fit cannot single out (it alone fixes some
    direction of the pose) moves the pose when it is left out; the model's covariance
    does not see it. Zeros below ``MIN_LEAVE_ONE_OUT`` reflectors; a j without which the
    normal equations are singular counts as no move."""
    if refl.x.shape[0] < MIN_LEAVE_ONE_OUT:
        return np.zeros((6, 6))
    r, J = residuals_jacobian(refl, R, t, tangent_bases(refl.e))
    return _spread_from(r, J)


@jit
def _spread_from(r, J):
    """``leave_one_out_spread``'s sum from the whitened residuals ``r`` (3m,) and their
    Jacobian ``J`` (3m, 6) at the pose (m >= ``MIN_LEAVE_ONE_OUT``)."""
    m = J.shape[0] // 3
    out = np.zeros((6, 6))
    H = gram(J)
    g = transposed_times(J, r)
    Hj = np.empty((6, 6))
    gj = np.empty(6)
    for j in range(m):
        for a in range(6):
            gj[a] = g[a]
            for b in range(6):
                Hj[a, b] = H[a, b]
        for k in range(3 * j, 3 * j + 3):
            for a in range(6):
                gj[a] -= J[k, a] * r[k]
                for b in range(6):
                    Hj[a, b] -= J[k, a] * J[k, b]
        L, ok = cholesky(Hj)
        if not ok:
            continue
        d = cholesky_solve(L, gj)  # -d_j; the sign drops out of d d^T
        for a in range(6):
            for b in range(6):
                out[a, b] += d[a] * d[b]
    f = (m - 1.0) / m
    for a in range(6):
        for b in range(6):
            out[a, b] *= f
    return out


@jit
def covariance_envelope(A, B):
    """(n, n): ``A`` widened to ``B`` in every direction where ``B`` is wider: with
    A = L L^T, the eigenvalues of L^-1 B L^-T below 1 are raised to 1 (the maximum of
    the two along the axes of that basis; the result contains both ellipsoids). ``A``
    (a copy) when it is not positive definite or anything is not finite."""
    n = A.shape[0]
    for a in range(n):
        for b in range(n):
            if not (np.isfinite(A[a, b]) and np.isfinite(B[a, b])):
                return A.copy()
    L, ok = cholesky(A)
    if not ok:
        return A.copy()
    X = lower_solve(L, B)  # L^-1 B
    M = lower_solve(L, X.T.copy())  # L^-1 B^T L^-T = L^-1 B L^-T (B symmetric)
    for a in range(n):  # exactly symmetric
        for b in range(a + 1, n):
            v = 0.5 * (M[a, b] + M[b, a])
            M[a, b] = v
            M[b, a] = v
    w, V = symmetric_eigen(M)
    LV = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            s = 0.0
            for k in range(a + 1):
                s += L[a, k] * V[k, b]
            LV[a, b] = s
    out = np.empty((n, n))
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for k in range(n):
                s += LV[a, k] * max(w[k], 1.0) * LV[b, k]
            out[a, b] = s
            out[b, a] = s
    return out


@jit
def _excess_sigma(z2, var, median_target, max_extra):
    """The smallest extra >= 0 with median(z2 * var / (var + extra^2)) <= median_target,
    by bisection to max_extra / 2^16; max_extra when even that does not reach it.
    z2 (m,) : squared residuals whitened by sqrt(var) (m,)."""
    scaled = np.empty(z2.shape[0])

    def median_scaled(extra):
        for i in range(z2.shape[0]):
            scaled[i] = z2[i] * var[i] / (var[i] + extra * extra)
        return median_inplace(scaled)

    if median_scaled(0.0) <= median_target:
        return 0.0
    if median_scaled(max_extra) > median_target:
        return max_extra
    lo, hi = 0.0, max_extra
    for _ in range(16):
        mid = 0.5 * (lo + hi)
        if median_scaled(mid) > median_target:
            lo = mid
        else:
            hi = mid
    return hi


@jit
def systematic_sigmas(refl, R, t, max_range_mm, max_bearing_rad):
    """The frame's excess range sigma (mm) and excess bearing sigma (rad) that its noise
    model lacks, estimated separately from the range and the lateral residuals (variance
    components) of the reflectors ``refl`` (a ``records.Reflectors``) at the pose (R, t):
    the smallest values with which the median squared whitened range residual equals the
    median of chi^2(1) and the median squared lateral pair that of chi^2(2), each capped
    by what the sensor can do (``max_range_mm``: uncalibrated ToF range errors;
    ``max_bearing_rad``: a matched centroid off by more than about half a pixel is a
    blend or a wrong blob, not noise). Separate components keep a range sigma from
    growing to absorb bearing errors (and the reverse)."""
    m = refl.x.shape[0]
    r, _ = residuals_jacobian(refl, R, t, tangent_bases(refl.e))
    lat2 = np.empty(m)
    rng2 = np.empty(m)
    var_b = np.empty(m)
    for i in range(m):
        lat2[i] = r[3 * i] ** 2 + r[3 * i + 1] ** 2
        rng2[i] = r[3 * i + 2] ** 2
        var_b[i] = refl.sb[i] ** 2
    extra_range = _excess_sigma(rng2, refl.sr**2, MEDIAN_CHI2_1DOF, max_range_mm)
    extra_bearing = _excess_sigma(lat2, var_b, MEDIAN_CHI2_2DOF, max_bearing_rad)
    return extra_range, extra_bearing


@jit
def line_of_sight(x, e, R, t, w, tol, max_iterations):
    """The paper's line-of-sight refinement (§5.2, Eqs. 51-52) from (R, t): project the
    predicted points on the measured lines of sight, re-solve the weighted SVD, stop when
    the residual sum changes by less than ``tol``. Returns R, t, iterations."""
    m = x.shape[0]
    prev = np.nan
    y = np.empty((m, 3))
    for it in range(1, max_iterations + 1):
        for i in range(m):
            s = 0.0
            for a in range(3):
                s += e[i, a] * (R[a, 0] * x[i, 0] + R[a, 1] * x[i, 1] + R[a, 2] * x[i, 2] + t[a])
            for a in range(3):
                y[i, a] = s * e[i, a]  # Eq. 51
        R, t = absolute_orientation(x, y, w)
        eps = 0.0
        for i in range(m):
            d2 = 0.0
            for a in range(3):
                d = R[a, 0] * x[i, 0] + R[a, 1] * x[i, 1] + R[a, 2] * x[i, 2] + t[a] - y[i, a]
                d2 += d * d
            eps += np.sqrt(d2)  # Eq. 52
        if it > 1 and abs(eps - prev) < tol:
            return R, t, it
        prev = eps
    return R, t, max_iterations


@jit
def subset(refl, keep):
    """The reflectors ``refl`` (a ``records.Reflectors``) of the rows where ``keep`` (m,)
    is true (a bool mask) or of the rows ``keep`` lists (indices)."""
    return Reflectors(
        x=refl.x[keep], e=refl.e[keep], rho=refl.rho[keep], sr=refl.sr[keep], sb=refl.sb[keep]
    )


@jit
def points(refl):
    """y = rho e (m, 3) mm of the reflectors ``refl`` (Eq. 8)."""
    y = np.empty(refl.e.shape)
    for i in range(y.shape[0]):
        for k in range(3):
            y[i, k] = refl.e[i, k] * refl.rho[i]
    return y


@jit
def fit_pose(refl, fit):
    """One fit of the reflectors ``refl`` (a ``records.Reflectors``): weighted SVD (Eqs.
    40-50) of their points rho e (Eq. 8), weights 1 / (sr^2 + (rho sb)^2), then the
    refinement ``fit.refinement`` (``fit`` : the ``core.records.FitSettings``); the ML
    evaluation at the final pose always. Returns its ``records.PoseFit`` (with the sigmas
    given)."""
    x, e, rho, sr, sb = refl.x, refl.e, refl.rho, refl.sr, refl.sb
    w = 1.0 / (sr**2 + (rho * sb) ** 2)
    R, t = absolute_orientation(x, points(refl), w)
    iterations = 0
    if fit.refinement == REFINE_LOS:
        R, t, iterations = line_of_sight(x, e, R, t, w, fit.los_tolerance, 200)
    max_it = 10 if fit.refinement == REFINE_ML else 0
    R_ml, t_ml, cov, chi2, its, norms = ml_refine(refl, R, t, max_it, 1e-7, fit.step_sigma2)
    if fit.refinement == REFINE_ML:
        R, t, iterations = R_ml, t_ml, its
    return PoseFit(
        R=R, t=t, iterations=iterations, covariance=cov, chi2=chi2, norms=norms, sr=sr, sb=sb
    )


@jit
def fit_without(j, refl, fit):
    """``fit_pose`` of every reflector but row j (the leave-one-out fits): returns the
    kept rows (m,) bool and the pose R, t."""
    keep = np.arange(refl.x.shape[0]) != j
    without = fit_pose(subset(refl, keep), fit)
    return keep, without.R, without.t


@jit
def fit_adaptive(refl, fit, max_bearing_rad):
    """``fit_pose`` with the noise model's sigmas ``refl.sr`` (mm), ``refl.sb`` (rad), then
    (``fit.adapt_range_sigma``, from 4 reflectors) again with the frame's excess range and
    bearing sigmas added (``systematic_sigmas``, capped at
    ``fit.max_systematic_range_sigma_mm`` and ``max_bearing_rad``, the centroid cap in
    rad): for each, the smallest estimate over the full fit and the fits leaving one
    reflector out, worst-fitting first, stopping at 0
    (``tofpose.stages.pose.solve.PoseSolver.solve`` documents why). Returns the
    ``records.PoseFit`` (its sigmas the ones used)."""
    first = fit_pose(refl, fit)
    m = refl.x.shape[0]
    if not fit.adapt_range_sigma or m < 4:
        return first
    max_range = fit.max_systematic_range_sigma_mm
    er, eb = systematic_sigmas(refl, first.R, first.t, max_range, max_bearing_rad)
    if (er > 0 or eb > 0) and m >= 5:
        order = np.argsort(-first.norms, kind="mergesort")
        for j in order:
            keep, Rj, tj = fit_without(j, refl, fit)
            er_j, eb_j = systematic_sigmas(subset(refl, keep), Rj, tj, max_range, max_bearing_rad)
            er, eb = min(er, er_j), min(eb, eb_j)
            if er <= 0 and eb <= 0:
                break
    if er <= 0 and eb <= 0:
        return first
    sr = np.sqrt(refl.sr**2 + er**2)
    sb = np.sqrt(refl.sb**2 + eb**2)
    return fit_pose(Reflectors(x=refl.x, e=refl.e, rho=refl.rho, sr=sr, sb=sb), fit)


@jit
def worst_outlier(refl, norms, fit):
    """Index of the reflector of ``refl`` (a ``records.Reflectors``, whose fit left the
    whitened norms ``norms`` (m,)) to drop, -1 when the fit is consistent
    (``tofpose.stages.pose.solve.PoseSolver.solve`` documents the rule; ``fit`` : the
    ``core.records.FitSettings``, its outlier_sigma and outlier_chi2_per_dof)."""
    m = norms.shape[0]
    worst = int(np.argmax(norms))
    dof = 3 * m - 6
    inconsistent = (norms**2).sum() > fit.outlier_chi2_per_dof * dof
    if m < 5:
        return worst if norms[worst] > fit.outlier_sigma else -1
    if norms[worst] <= fit.outlier_sigma and not inconsistent:
        return -1
    # the one to drop is the one the others predict worst: a biased point with a small
    # sigma drags the fit towards itself, so that its own residual is small and good
    # points' residuals are large (masking); a fit without it shows it
    predicted = np.empty(m)
    for j in range(m):
        predicted[j] = deleted_residual_norm(j, refl, fit)
    worst = int(np.argmax(predicted))
    return worst if predicted[worst] > fit.outlier_sigma else -1


@jit
def deleted_residual_norm(j, refl, fit):
    """How far the fit without reflector j (of ``refl``, a ``records.Reflectors``)
    predicts it, in sigmas of that prediction (ours): sqrt(r^T S^-1 r), r (3,) its
    whitened residuals at the pose fitted without it, S = I + J_j C J_j^T (3, 3) with
    J_j (3, 6) their Jacobian there and C (6, 6) that fit's covariance (its J^T J
    inverse): the deleted residual in sigmas of its prediction. The pose of the others is uncertain
    most where j alone fixes it (the only marker on one side of the pattern), and a
    good marker there is predicted badly by them; S counts that. 0 when the others
    cannot fix the pose (C singular): nothing tells j is wrong."""
    keep = np.arange(refl.x.shape[0]) != j
    without = fit_pose(subset(refl, keep), fit)
    C = without.covariance
    if not np.isfinite(C).all():
        return 0.0
    one = Reflectors(
        x=refl.x[j : j + 1],
        e=refl.e[j : j + 1],
        rho=refl.rho[j : j + 1],
        sr=refl.sr[j : j + 1],
        sb=refl.sb[j : j + 1],
    )
    r, Jj = residuals_jacobian(one, without.R, without.t, tangent_bases(one.e))
    S = np.eye(3) + Jj @ C @ Jj.T
    return np.sqrt(max(float(r @ np.linalg.solve(S, r)), 0.0))


#: Gauss-Newton steps of the common range offset's estimate (from a converged 6-parameter fit)
OFFSET_ITERATIONS = 3


#: no offset estimated


@jit
def mean_bearing(e):
    """The unit mean (3,) of bearings e (m, 3)."""
    mean = np.zeros(3)
    for i in range(e.shape[0]):
        mean += e[i]
    return mean / np.sqrt((mean**2).sum())


@jit
def pattern_scale_sigma(e, prior):
    """Prior sigma (relative) of the image scale for bearings e (m, 3): focal-length
    calibration and common-mode centroid error over the pattern's rms angular radius,
    in quadrature; also returns the unit mean bearing (3,)."""
    m = e.shape[0]
    mean = mean_bearing(e)
    r2 = 0.0
    for i in range(m):
        c = e[i, 0] * mean[0] + e[i, 1] * mean[1] + e[i, 2] * mean[2]
        r2 += 1.0 - c * c
    r_rms = np.sqrt(max(r2 / m, 1e-12))
    bias = prior.centroid_bias_rad / r_rms
    return np.sqrt(prior.focal_length_sigma_rel**2 + bias * bias), mean


@jit
def scale_directions(e, B, mean):
    """(m, 2): the tangent components of a unit image-scale error about the unit mean
    bearing ``mean`` (3,), for bearings e (m, 3) with tangent bases B (m, 2, 3): the
    true bearing is e_i - kappa (e_i - mean (e_i.mean)) to first order, whose tangent
    components are -kappa (e_i.mean) (B_ik.mean)."""
    out = np.empty((e.shape[0], 2))
    for i in range(e.shape[0]):
        c = e[i, 0] * mean[0] + e[i, 1] * mean[1] + e[i, 2] * mean[2]
        for k in range(2):
            bm = B[i, k, 0] * mean[0] + B[i, k, 1] * mean[1] + B[i, k, 2] * mean[2]
            out[i, k] = -c * bm
    return out


@jit
def common_range_offset(refl, R0, t0, prior):
    """The range offset b (mm) common to every reflector of ``refl`` (a
    ``records.Reflectors``; ranges read ``|p| + b``), with the pose and the image scale,
    by Gauss-Newton on (rotation, translation, b, kappa) from (R0, t0). kappa: the
    measured bearings' offsets from the pattern's mean bearing are (1 + kappa) times the
    true ones (a focal-length error, or a centroid error common to the frame's small
    markers); it is what lets the image scale fix the distance, so it is estimated with
    its prior (``pattern_scale_sigma``) rather than assumed exact: a scale error of 1 %
    at 6 m is 60 mm of range. Priors b ~ N(prior.mean_mm, prior.sigma_mm^2) and kappa ~ N(0,
    sigma_kappa^2) enter as two more residuals (prior: a ``records.RangeOffsetPrior``).
    The image scale determines b when the target is large enough in the image and the
    scale is known well enough; otherwise the priors keep it near 0. Returns b, its
    posterior sigma (mm, kappa marginalised)."""
    x, e, rho, sr, sb = refl.x, refl.e, refl.rho, refl.sr, refl.sb
    m = x.shape[0]
    prior_sigma_mm = prior.sigma_mm
    prior_mean_mm = prior.mean_mm
    if prior_sigma_mm <= 0:
        return prior_mean_mm, 0.0
    sigma_kappa, mean = pattern_scale_sigma(e, prior)
    R, t, b = R0.copy(), t0.copy(), prior_mean_mm
    B = tangent_bases(e)
    scale_column = scale_directions(e, B, mean)
    fit_scale = sigma_kappa > 0  # else the scale is taken as exact: kappa stays 0
    inv_sigma_kappa = 1.0 / sigma_kappa if fit_scale else 1.0
    if not fit_scale:
        scale_column[:] = 0.0
    J8 = np.zeros((3 * m + 2, 8))
    r8 = np.zeros(3 * m + 2)
    kappa = 0.0
    sigma_b = prior_sigma_mm
    for _ in range(OFFSET_ITERATIONS):
        r, J = residuals_jacobian(Reflectors(x=x, e=e, rho=rho - b, sr=sr, sb=sb), R, t, B)
        for i in range(3 * m):
            r8[i] = r[i]
            for k in range(6):
                J8[i, k] = J[i, k]
        for i in range(m):
            lat = max((rho[i] - b) * sb[i], 1e-6)
            for k in range(2):
                col = (rho[i] - b) * scale_column[i, k] / lat
                J8[3 * i + k, 7] = col
                # the lateral sigma (rho - b) sigma_b moves with b: a lateral residual
                # d / ((rho - b) sb) grows as d / (rho - b)^2 sb per mm of b
                J8[3 * i + k, 6] = r[3 * i + k] / max(rho[i] - b, 1e-6)
                r8[3 * i + k] += kappa * col
            J8[3 * i + 2, 6] = 1.0 / sr[i]
        r8[3 * m] = (b - prior_mean_mm) / prior_sigma_mm
        J8[3 * m, 6] = 1.0 / prior_sigma_mm
        r8[3 * m + 1] = kappa * inv_sigma_kappa
        J8[3 * m + 1, 7] = inv_sigma_kappa
        L, ok = cholesky(gram(J8))
        if not ok:
            return prior_mean_mm, prior_sigma_mm
        delta = -cholesky_solve(L, transposed_times(J8, r8))
        R = matmul3(rotation_step(delta[:3]), R)
        t = t + delta[3:6]
        b = b + delta[6]
        kappa = kappa + delta[7]
        sigma_b = np.sqrt(cholesky_inverse(L)[6, 6])
    return b, sigma_b


@jit
def fit_with_outliers(refl, fit, max_bearing_rad, offset_prior):
    """``fit_adaptive``; then (``fit.reject_outliers``) drop the worst outlier and refit
    while one is found and more than ``fit.min_matches`` remain; then
    (``offset_prior.sigma_mm`` > 0, a ``records.RangeOffsetPrior``; ML refinement, 4
    reflectors kept or more) the range offset common to the kept reflectors
    (``common_range_offset``: its posterior mean, which the priors shrink towards 0 when
    the frame cannot tell it) taken out of their ranges and the fit repeated.

    refl : the matched reflectors (a ``records.Reflectors``: catalog points, bearings,
    ranges and the noise model's sigmas, mm and rad); fit : the ``core.records.
    FitSettings``; max_bearing_rad : its centroid cap in rad (px over fx). Returns the
    ``records.OutlierFit``: the kept rows (m,) bool, the final fit of the kept
    reflectors, the common offset b (mm, 0 when not estimated) and its posterior sigma
    (mm; the prior's when not estimated)."""
    m = refl.x.shape[0]
    kept = np.ones(m, np.bool_)
    rows = np.arange(m)
    result = fit_adaptive(refl, fit, max_bearing_rad)
    while fit.reject_outliers and rows.shape[0] > fit.min_matches:
        worst = worst_outlier(
            Reflectors(x=refl.x, e=refl.e, rho=refl.rho, sr=result.sr, sb=result.sb),
            result.norms,
            fit,
        )
        if worst < 0:
            break
        kept[rows[worst]] = False
        keep = np.arange(rows.shape[0]) != worst
        rows = rows[keep]
        refl = subset(refl, keep)
        result = fit_adaptive(refl, fit, max_bearing_rad)
    # the common offset from the reflectors kept: a reflection left in would bend the
    # fit the offset is estimated from
    # not estimated: the prior's mean (0 unless one was learned) and sigma
    offset, offset_sigma = offset_prior.mean_mm, offset_prior.sigma_mm
    if offset_prior.sigma_mm > 0 and fit.refinement == REFINE_ML and rows.shape[0] >= 4:
        used = Reflectors(x=refl.x, e=refl.e, rho=refl.rho, sr=result.sr, sb=result.sb)
        offset, offset_sigma = common_range_offset(used, result.R, result.t, offset_prior)
    if offset != 0.0:
        shifted = Reflectors(x=refl.x, e=refl.e, rho=refl.rho - offset, sr=refl.sr, sb=refl.sb)
        result = fit_adaptive(shifted, fit, max_bearing_rad)
    return OutlierFit(kept=kept, fit=result, offset_mm=offset, offset_sigma_mm=offset_sigma)


@jit
def range_bias_covariance(refl, R, t, bias_sigma_mm):
    """(6, 6) pose covariance from a range offset common to every reflector of ``refl``
    (a ``records.Reflectors``), of sigma ``bias_sigma_mm``: s s^T sigma_b^2 with s =
    (J^T J)^-1 J^T g, g the whitened residuals' response to a unit offset (-1 / sr on
    each range row)."""
    _, J = residuals_jacobian(refl, R, t, tangent_bases(refl.e))
    L, ok = cholesky(gram(J))
    return _range_bias_from(refl, J, L, ok, bias_sigma_mm)


@jit
def _range_bias_from(refl, J, L, ok, bias_sigma_mm):
    """``range_bias_covariance`` from the Jacobian ``J`` (3m, 6) at the pose and the
    Cholesky factor ``L`` (6, 6) of J^T J (``ok`` False: singular, NaN)."""
    if not ok:
        return np.full((6, 6), np.nan)
    g = np.zeros(J.shape[0])
    for i in range(refl.x.shape[0]):
        g[3 * i + 2] = -1.0 / refl.sr[i]
    s = cholesky_solve(L, transposed_times(J, g))
    return bias_sigma_mm**2 * np.outer(s, s)


@jit
def class_scale_covariance(refl, R, t, group, n_groups, bias_rad, common_scale_sigma):
    """(6, 6) pose covariance from image-scale errors of the reflectors ``refl`` (a
    ``records.Reflectors``; bearings scaled about the pattern's mean bearing by 1 + kappa,
    as in ``common_range_offset``): one common to every reflector, of relative sigma
    ``common_scale_sigma`` (the focal length's calibration and the markers' common
    centroid error, ``pattern_scale_sigma``), and one per group of
    reflectors (``group`` (m,) int in [0, n_groups): the markers of one diameter),
    independent between groups, from a centroid error ``bias_rad`` common to a group's
    markers: sigma ``bias_rad / r_g`` (r_g the group's rms angle from the mean bearing).
    Sum of s s^T sigma^2, s = (J^T J)^-1 J^T g, g the whitened residuals' response to a
    unit kappa."""
    B = tangent_bases(refl.e)
    _, J = residuals_jacobian(refl, R, t, B)
    L, ok = cholesky(gram(J))
    return _class_scale_from(refl, B, J, L, ok, group, n_groups, bias_rad, common_scale_sigma)


@jit
def _class_scale_from(refl, B, J, L, ok, group, n_groups, bias_rad, common_scale_sigma):
    """``class_scale_covariance`` from the tangent bases ``B`` (m, 2, 3), the Jacobian
    ``J`` (3m, 6) at the pose and the Cholesky factor ``L`` of J^T J (``ok`` False:
    singular, NaN)."""
    if not ok:
        return np.full((6, 6), np.nan)
    e, rho, sb = refl.e, refl.rho, refl.sb
    m = e.shape[0]
    mean = mean_bearing(e)
    response = scale_directions(e, B, mean)  # d(lateral residual) / d(kappa), whitened
    r2 = np.zeros(m)
    for i in range(m):
        c = e[i, 0] * mean[0] + e[i, 1] * mean[1] + e[i, 2] * mean[2]
        r2[i] = 1.0 - c * c
        response[i] *= rho[i] / max(rho[i] * sb[i], 1e-6)
    out = np.zeros((6, 6))
    for k in range(-1, n_groups):  # -1: the common scale
        g = np.zeros(J.shape[0])
        r2_sum, n = 0.0, 0
        for i in range(m):
            if k >= 0 and group[i] != k:
                continue
            r2_sum += r2[i]
            n += 1
            g[3 * i] = response[i, 0]
            g[3 * i + 1] = response[i, 1]
        if n == 0:
            continue
        sigma = common_scale_sigma if k < 0 else bias_rad / np.sqrt(max(r2_sum / n, 1e-12))
        if sigma <= 0:
            continue
        s = cholesky_solve(L, transposed_times(J, g))
        out += sigma**2 * np.outer(s, s)
    return out


@jit
def concluding_covariances(refl, R, t, terms):
    """The covariances a concluded fit reports beside the model's (ours), in one call
    and from one Jacobian: ``range_bias_covariance`` (when ``terms.bias_sigma_mm`` > 0),
    ``class_scale_covariance`` (when ``terms.by_size``) and ``leave_one_out_spread``
    (when ``terms.leave_one_out``) of the fitted reflectors ``refl`` (a
    ``records.Reflectors``) at the pose R (3, 3), t (3,) mm; ``terms`` a
    ``records.CovarianceTerms``. Returns a ``records.ConcludingCovariances``: each (6, 6),
    zeros where its term is off, the values of the three kernels."""
    B = tangent_bases(refl.e)
    r, J = residuals_jacobian(refl, R, t, B)
    L, ok = cholesky(gram(J))
    zeros = np.zeros((6, 6))
    range_bias = (
        _range_bias_from(refl, J, L, ok, terms.bias_sigma_mm) if terms.bias_sigma_mm > 0 else zeros
    )
    by_size = (
        _class_scale_from(
            refl,
            B,
            J,
            L,
            ok,
            terms.group,
            terms.n_groups,
            terms.bias_rad,
            terms.common_scale_sigma,
        )
        if terms.by_size
        else zeros
    )
    spread = (
        _spread_from(r, J)
        if terms.leave_one_out and refl.x.shape[0] >= MIN_LEAVE_ONE_OUT
        else zeros
    )
    return ConcludingCovariances(range_bias=range_bias, by_size=by_size, spread=spread)


@jit
def point_residuals_mm(x, y, R, t):
    """|y_i - (R x_i + t)| (m,) mm of matched points x (m, 3) (target frame) and y (m, 3)
    (camera frame), and their RMS."""
    m = x.shape[0]
    out = np.empty(m)
    s = 0.0
    for i in range(m):
        d2 = 0.0
        for a in range(3):
            d = y[i, a] - (R[a, 0] * x[i, 0] + R[a, 1] * x[i, 1] + R[a, 2] * x[i, 2] + t[a])
            d2 += d * d
        out[i] = np.sqrt(d2)
        s += d2
    return out, np.sqrt(s / m)
