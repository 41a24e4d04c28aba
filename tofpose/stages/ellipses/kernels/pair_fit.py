"""Two blurred discs fitted to a merged pair's pixels, compiled: the model of
``tofpose.stages.ellipses.pair_fit`` (its docstring has the equations) and a box-constrained
Levenberg-
Marquardt loop on its 9 parameters.

SciPy's ``least_squares`` (the reference, ``reference.pair_fit.fit_pair_lm``) spends ~10 ms
on one pair, most of it in per-iteration Python and LAPACK overhead on a 9-parameter
problem; this loop does the same fit in one compiled call. Parameters p (9,):
u1, v1, u2, v2 (px), a1, a2 (counts), r (px), s (px), bg (counts); sub-samples su, sv
(n, S) px; pixel values (n,).
"""

from __future__ import annotations

import math

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.small_matrices import cholesky, cholesky_solve
from tofpose.stages.ellipses.constants import N_PARAMS

_SQRT2 = math.sqrt(2.0)
_SQRTPI = math.sqrt(math.pi)


#: Abramowitz & Stegun 7.1.26: erfc(z) = t (a1 + t (a2 + ...)) exp(-z^2), t = 1/(1 + p z),
#: z >= 0, absolute error <= 1.5e-7 (the model needs exp(-z^2) for its Jacobian anyway,
#: so the coverage costs no second transcendental call)
_AS_P = 0.3275911
_AS_A = (0.254829592, -0.284496736, 1.421413741, -1.453152027, 1.061405429)
#: beyond |z| = 4.5 erfc(z)/2 is within 1e-10 of 0 or 1 and exp(-z^2) below 2e-9
_Z_FLAT = 4.5


@jit
def half_erfc(z, g):
    """erfc(z) / 2 from z and g = exp(-z^2) (A&S 7.1.26; erfc(-z) = 2 - erfc(z))."""
    x = abs(z)
    t = 1.0 / (1.0 + _AS_P * x)
    poly = t * (_AS_A[0] + t * (_AS_A[1] + t * (_AS_A[2] + t * (_AS_A[3] + t * _AS_A[4]))))
    half = 0.5 * poly * g
    return half if z >= 0.0 else 1.0 - half


@jit
def pair_model(p, su, sv, values, jac):
    """Residuals (n,) model minus ``values``, and the Jacobian d residuals / d p written
    into ``jac`` (n, 9) (d/dz erfc(z)/2 = -exp(-z^2)/sqrt(pi))."""
    n, n_sub = su.shape
    res = np.empty(n)
    s = p[7]
    k_c = 1.0 / (_SQRTPI * _SQRT2 * s)
    for i in range(n):
        for j in range(N_PARAMS):
            jac[i, j] = 0.0
        model = p[8]
        for k in range(2):
            cu, cv, a = p[2 * k], p[2 * k + 1], p[4 + k]
            cover = 0.0
            g_ux = 0.0
            g_uy = 0.0
            g_sum = 0.0
            gz_sum = 0.0
            for m in range(n_sub):
                du = su[i, m] - cu
                dv = sv[i, m] - cv
                dist = max(math.sqrt(du * du + dv * dv), 1e-9)
                z = (dist - p[6]) / (_SQRT2 * s)
                if z > _Z_FLAT:
                    continue  # outside the blurred edge: no light, no slope
                if z < -_Z_FLAT:
                    cover += 1.0  # inside it: full light, no slope
                    continue
                g = math.exp(-z * z)
                cover += half_erfc(z, g)
                g_ux += g * du / dist
                g_uy += g * dv / dist
                g_sum += g
                gz_sum += g * z
            cover /= n_sub
            model += a * cover
            jac[i, 2 * k] = a * k_c * g_ux / n_sub
            jac[i, 2 * k + 1] = a * k_c * g_uy / n_sub
            jac[i, 4 + k] = cover
            jac[i, 6] += a * k_c * g_sum / n_sub
            jac[i, 7] += a * gz_sum / n_sub / (_SQRTPI * s)
        jac[i, 8] = 1.0
        res[i] = model - values[i]
    return res


@jit
def _normal_equations(res, jac):
    """J^T J (9, 9), J^T r (9,) and r^T r."""
    n = res.shape[0]
    H = np.zeros((N_PARAMS, N_PARAMS))
    g = np.zeros(N_PARAMS)
    cost = 0.0
    for i in range(n):
        cost += res[i] * res[i]
        for a in range(N_PARAMS):
            g[a] += jac[i, a] * res[i]
            for b in range(a, N_PARAMS):
                H[a, b] += jac[i, a] * jac[i, b]
    for a in range(N_PARAMS):
        for b in range(a):
            H[a, b] = H[b, a]
    return H, g, cost


@jit
def fit_pair_lm(
    su, sv, values, start, lower, upper, max_iterations, centre_tolerance_px, cost_tolerance
):
    """Levenberg-Marquardt (Marquardt's diagonal scaling) from ``start`` (9,) inside the
    box ``lower``..``upper`` (9,): each step is clipped to the box (a projected step).
    Returns (p (9,), J^T J (9, 9) at p, r^T r at p, converged): converged when the next
    step would move no centre coordinate by more than ``centre_tolerance_px`` (the
    centres are what the fit is for; radius, blur, gains and level are nuisance), or an
    accepted step lowered the cost by less than ``cost_tolerance`` relative (MINPACK's
    xtol / ftol tests); False when ``max_iterations`` run out or the damping runs away."""
    n = su.shape[0]
    jac = np.empty((n, N_PARAMS))
    jac_try = np.empty((n, N_PARAMS))
    p = np.minimum(np.maximum(start, lower), upper)
    res = pair_model(p, su, sv, values, jac)
    H, g, cost = _normal_equations(res, jac)
    damping = 1e-3
    for _ in range(max_iterations):
        A = H.copy()
        for a in range(N_PARAMS):
            A[a, a] += damping * max(H[a, a], 1e-12)
        L, ok = cholesky(A)
        if not ok:
            damping *= 10.0
            if damping > 1e12:
                return p, H, cost, False
            continue
        step = cholesky_solve(L, -g)
        trial = np.minimum(np.maximum(p + step, lower), upper)
        moved_px = 0.0
        for a in range(4):
            moved_px = max(moved_px, abs(trial[a] - p[a]))
        if moved_px < centre_tolerance_px:
            return p, H, cost, True  # a step below the tolerance: converged
        res_try = pair_model(trial, su, sv, values, jac_try)
        H_try, g_try, cost_try = _normal_equations(res_try, jac_try)
        if cost_try < cost:
            gain = (cost - cost_try) / max(cost, 1e-300)
            p, H, g, cost = trial, H_try, g_try, cost_try
            jac, jac_try = jac_try, jac
            damping = max(damping * 0.3, 1e-9)
            if gain < cost_tolerance:
                return p, H, cost, True
        else:
            damping *= 4.0
            if damping > 1e12:
                return p, H, cost, False
    return p, H, cost, False
