"""Pose from matched reflectors (§5), compiled: weighted SVD (Eqs. 40-50), the whitened
residuals and Jacobian of the ToF measurement model (Eq. 10), Gauss-Newton maximum-
likelihood refinement with its covariance, and the frame's systematic range sigma.

The readable specification, input checks and docstrings are in ``tofpose.pose``, whose
functions call these; shapes: x, e (m, 3); rho, sigmas (m,); R (3, 3); t (3,).
"""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


@jit
def svd_pose(x, y, w):
    """Weighted absolute orientation: R (3, 3), t (3,) minimising
    ``sum w_i ||y_i - (R x_i + t)||^2`` (Eqs. 40-50)."""
    ws = w / w.sum()
    x_bar = ws @ x  # Eq. 41
    y_bar = ws @ y
    xc = x - x_bar  # Eq. 42
    yc = y - y_bar
    S = (xc * w.reshape(-1, 1)).T @ yc  # Eq. 45
    U, _, Vt = np.linalg.svd(S)
    V = Vt.T
    d = np.sign(np.linalg.det(V @ U.T))
    D = np.eye(3)
    D[2, 2] = d if d != 0 else 1.0
    R = V @ D @ U.T  # Eq. 49
    return R, y_bar - R @ x_bar  # Eq. 50


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
def residuals_jacobian(x, e, rho, R, t, sr, sb, B):
    """Whitened residuals r (3m,) and Jacobian J (3m, 6) of the ToF model (Eq. 10): per
    reflector two lateral residuals (over range * sigma_bearing) and one range residual
    (over sigma_range); parameters: small left rotation (rad) then translation (mm).
    B : ``tangent_bases(e)``."""
    m = x.shape[0]
    r = np.empty(3 * m)
    J = np.zeros((3 * m, 6))
    for i in range(m):
        rx0 = R[0, 0] * x[i, 0] + R[0, 1] * x[i, 1] + R[0, 2] * x[i, 2]
        rx1 = R[1, 0] * x[i, 0] + R[1, 1] * x[i, 1] + R[1, 2] * x[i, 2]
        rx2 = R[2, 0] * x[i, 0] + R[2, 1] * x[i, 1] + R[2, 2] * x[i, 2]
        p0, p1, p2 = rx0 + t[0], rx1 + t[1], rx2 + t[2]
        lat = max(rho[i] * sb[i], 1e-6)
        # rows of d(R x + t) / d(w, t): dP[:, 0:3] = -[R x]_x, dP[:, 3:6] = I
        dP = np.array([
            [0.0, rx2, -rx1, 1.0, 0.0, 0.0],
            [-rx2, 0.0, rx0, 0.0, 1.0, 0.0],
            [rx1, -rx0, 0.0, 0.0, 0.0, 1.0],
        ])  # fmt: skip
        for k in range(2):
            b0, b1, b2 = B[i, k, 0], B[i, k, 1], B[i, k, 2]
            r[3 * i + k] = (b0 * p0 + b1 * p1 + b2 * p2) / lat
            for c in range(6):
                J[3 * i + k, c] = (b0 * dP[0, c] + b1 * dP[1, c] + b2 * dP[2, c]) / lat
        e0, e1, e2 = e[i, 0], e[i, 1], e[i, 2]
        r[3 * i + 2] = ((e0 * p0 + e1 * p1 + e2 * p2) - rho[i]) / sr[i]
        for c in range(6):
            J[3 * i + 2, c] = (e0 * dP[0, c] + e1 * dP[1, c] + e2 * dP[2, c]) / sr[i]
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
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


@jit
def ml_refine(x, e, rho, R0, t0, sr, sb, max_iterations, tol, step_sigma2):
    """Gauss-Newton on bearings and ranges together (ours, beyond §5.2) from (R0, t0).

    Stops when a step is below ``tol`` (mm / rad) or below ``step_sigma2`` in squared
    sigmas of the pose. Returns R, t, covariance (6, 6) = (J^T J)^-1 at the final pose
    (NaN when singular), chi^2, iterations, per-reflector whitened norms (m,).
    """
    R, t = R0.copy(), t0.copy()
    B = tangent_bases(e)
    iterations = 0
    for it in range(1, max_iterations + 1):
        iterations = it
        r, J = residuals_jacobian(x, e, rho, R, t, sr, sb, B)
        H = J.T @ J
        if abs(np.linalg.det(H)) == 0.0:
            break
        delta = -np.linalg.solve(H, J.T @ r)
        R = rotation_step(delta[:3]) @ R
        t = t + delta[3:]
        if np.sqrt((delta**2).sum()) < tol or delta @ H @ delta < step_sigma2:
            break
    r, J = residuals_jacobian(x, e, rho, R, t, sr, sb, B)
    H = J.T @ J
    cov = np.full((6, 6), np.nan) if abs(np.linalg.det(H)) == 0.0 else np.linalg.inv(H)
    return R, t, cov, r @ r, iterations, reflector_norms(r)


@jit
def _median(v):
    n = v.shape[0]
    k = n >> 1
    s = np.partition(v.copy(), k)
    return s[k] if n & 1 else (s[:k].max() + s[k]) / 2.0


@jit
def systematic_sigma(x, e, rho, R, t, sr, sb, max_mm, median_chi2):
    """The smallest sigma_s >= 0 (mm) with which the median squared whitened residual
    of the reflectors equals ``median_chi2`` (range sigmas sqrt(sr^2 + sigma_s^2)), by
    bisection to max_mm / 2^16; 0 when the model already fits, max_mm when even that
    does not."""
    m = x.shape[0]
    r, _ = residuals_jacobian(x, e, rho, R, t, np.ones(m), sb, tangent_bases(e))
    lat2 = np.empty(m)
    rng2 = np.empty(m)
    for i in range(m):
        lat2[i] = r[3 * i] ** 2 + r[3 * i + 1] ** 2
        rng2[i] = r[3 * i + 2] ** 2
    var = sr**2

    def median_z2(extra):
        return _median(lat2 + rng2 / (var + extra**2))

    if median_z2(0.0) <= median_chi2:
        return 0.0
    if median_z2(max_mm) > median_chi2:
        return max_mm
    lo, hi = 0.0, max_mm
    for _ in range(16):
        mid = 0.5 * (lo + hi)
        if median_z2(mid) > median_chi2:
            lo = mid
        else:
            hi = mid
    return hi
