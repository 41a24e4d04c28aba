"""§5 as stated: the weighted absolute orientation (Eqs. 40-50) by the SVD, the
line-of-sight refinement (Eqs. 51-52), and ours: the maximum-likelihood pose on the ToF
measurement model (Eq. 10) by SciPy's least squares, its covariance, the leave-one-out
spread and the covariance envelope.

Shapes: x (m, 3) catalog points mm; e (m, 3) unit bearings; rho, sr (m,) mm; sb (m,) rad;
R (3, 3); t (3,) mm. A pose perturbation is (w, dt): R <- exp([w]x) R, t <- t + dt (the
rotation vector in the camera frame, rad; the covariance's order).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

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


def whitened_residuals(x, e, rho, R, t, sr, sb) -> np.ndarray:
    """(3m,): per reflector the predicted point's two components across its line of sight
    over ``rho sigma_bearing`` (at least ``MIN_LATERAL_SIGMA_MM``), and its distance along
    it minus the measured range over ``sigma_range`` (Eq. 10: y~ = (rho + d_rho)(e +
    d_e))."""
    p = np.asarray(x, float) @ R.T + t
    B = tangent_basis(e)
    lateral = np.einsum("mkj,mj->mk", B, p) / np.maximum(rho * sb, MIN_LATERAL_SIGMA_MM)[:, None]
    along = (np.einsum("mj,mj->m", e, p) - rho) / sr
    return np.column_stack((lateral, along)).ravel()


def _perturbed(R, t, params):
    return Rotation.from_rotvec(params[:3]).as_matrix() @ R, t + params[3:]


def jacobian(x, e, rho, R, t, sr, sb, step=1e-7) -> np.ndarray:
    """(3m, 6): the whitened residuals' derivative by (w, dt) at (R, t), by central
    differences (steps of ``step`` rad and ``step`` x 1000 mm)."""
    J = np.empty((3 * len(x), 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = step if k < 3 else step * 1000.0
        plus = whitened_residuals(x, e, rho, *_perturbed(R, t, d), sr, sb)
        minus = whitened_residuals(x, e, rho, *_perturbed(R, t, -d), sr, sb)
        J[:, k] = (plus - minus) / (2.0 * d[k])
    return J


def ml_refine(x, e, rho, R0, t0, sr, sb):
    """The maximum-likelihood pose (ours, beyond §5.2): the (R, t) minimising the sum of
    squared ``whitened_residuals``, from (R0, t0), by SciPy's Levenberg-Marquardt.
    Returns R, t, covariance (6, 6) = (J^T J)^-1 at the optimum, chi^2."""

    def fun(params):
        return whitened_residuals(x, e, rho, *_perturbed(R0, t0, params), sr, sb)

    sol = least_squares(fun, np.zeros(6), method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    R, t = _perturbed(R0, t0, sol.x)
    J = jacobian(x, e, rho, R, t, sr, sb)
    return R, t, np.linalg.inv(J.T @ J), float((sol.fun**2).sum())


def leave_one_out_spread(x, e, rho, R, t, sr, sb) -> np.ndarray:
    """(6, 6), ours: ``(m - 1) / m sum_j d_j d_j^T``, d_j the Gauss-Newton step from (R, t)
    of the fit without reflector j, ``-(H - H_j)^-1 (g - g_j)`` with H = J^T J, g = J^T r
    and H_j, g_j reflector j's part; a j without which H - H_j is singular adds nothing;
    zeros below 4 reflectors."""
    m = len(x)
    out = np.zeros((6, 6))
    if m < 4:
        return out
    r = whitened_residuals(x, e, rho, R, t, sr, sb)
    J = jacobian(x, e, rho, R, t, sr, sb)
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
