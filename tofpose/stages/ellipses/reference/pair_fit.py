"""The model fit of two reflectors imaged as one blob, as stated (ours, not in the paper:
markers 7 and 8 beyond ~6 m, after §3.3's split; ``tofpose.stages.ellipses.pair_fit`` has the why):

    I(p) = bg + a_1 C(p; c_1, r, s) + a_2 C(p; c_2, r, s),
    C(p; c, r, s) = mean over the pixel's sub-samples q of erfc((|q - c| - r) / (sqrt 2 s)) / 2,

two discs of one radius r with edges blurred by a Gaussian of sigma s, amplitudes a_k and
a local level bg, fitted to the pixels by SciPy's bounded least squares.

Same names, arguments and results as ``tofpose.stages.ellipses.kernels.pair_fit``. Parameters p
(9,):
u1, v1, u2, v2 (px), a1, a2 (counts), r (px), s (px), bg (counts); sub-samples su, sv
(n, S) px; pixel values (n,).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfc

from tofpose.stages.ellipses.constants import N_PARAMS

#: SciPy's step and gradient tolerances of the fit: tight, so that it ends at the optimum
#: the kernel's tolerances stop near
FIT_TOLERANCE = 1e-12


def half_erfc(z, g):
    """The blurred edge: erfc(z) / 2 (SciPy's, to double precision). g = exp(-z^2) is
    the kernel's shortcut and is not needed."""
    del g
    return 0.5 * erfc(z)


def pair_model(p, su, sv, values, jac):
    """Residuals (n,) I(p) - ``values``; the Jacobian d residuals / d p written into
    ``jac`` (n, 9). With z = (d - r) / (sqrt 2 s), d = |q - c| (at least 1e-9) and
    k(z) = exp(-z^2) / (sqrt(2 pi) s) = -d/dd erfc(z)/2: dC/dc = mean(k (q - c) / d),
    dC/dr = mean(k), dC/ds = mean(k sqrt(2) z); dI/da_k = C_k, dI/dbg = 1."""
    u1, v1, u2, v2, a1, a2, r, s, bg = np.asarray(p, float)
    model = np.full(su.shape[0], bg)
    jac[:] = 0.0
    jac[:, 8] = 1.0
    for k, (cu, cv, a) in enumerate(((u1, v1, a1), (u2, v2, a2))):
        du, dv = su - cu, sv - cv
        d = np.maximum(np.hypot(du, dv), 1e-9)
        z = (d - r) / (np.sqrt(2.0) * s)
        slope = np.exp(-z * z) / (np.sqrt(2.0 * np.pi) * s)
        cover = half_erfc(z, None).mean(axis=1)
        model += a * cover
        jac[:, 2 * k] = a * (slope * du / d).mean(axis=1)
        jac[:, 2 * k + 1] = a * (slope * dv / d).mean(axis=1)
        jac[:, 4 + k] = cover
        jac[:, 6] += a * slope.mean(axis=1)
        jac[:, 7] += a * (slope * np.sqrt(2.0) * z).mean(axis=1)
    return model - values


def _normal_equations(res, jac):
    """The Gauss-Newton normal equations' J^T J (9, 9), J^T r (9,) and the cost r^T r."""
    return jac.T @ jac, jac.T @ res, float(res @ res)


def fit_pair_lm(
    su, sv, values, start, lower, upper, max_iterations, centre_tolerance_px, cost_tolerance
):
    """The least-squares fit of ``pair_model`` from ``start`` (9,) clipped into the box
    ``lower``..``upper`` (9,), by SciPy's bounded trust-region reflective
    ``least_squares`` (analytic Jacobian, Jacobian scaling, at most ``max_iterations``
    evaluations; ``ftol`` = ``cost_tolerance``, ``xtol`` = ``gtol`` = ``FIT_TOLERANCE``).
    Returns (p (9,), J^T J (9, 9) at p, r^T r at p, converged = SciPy's success).

    The kernel's own Levenberg-Marquardt stops once a step would move no centre by more
    than ``centre_tolerance_px``; this fit runs on to SciPy's tolerance, so the two agree
    to about that tolerance (the reference does not use it)."""
    del centre_tolerance_px
    n = su.shape[0]

    def residuals(p):
        return pair_model(p, su, sv, values, np.empty((n, N_PARAMS)))

    def jacobian(p):
        jac = np.empty((n, N_PARAMS))
        pair_model(p, su, sv, values, jac)
        return jac

    fit = least_squares(
        residuals,
        np.clip(start, lower, upper),
        jac=jacobian,
        bounds=(lower, upper),
        x_scale="jac",
        ftol=cost_tolerance,
        xtol=FIT_TOLERANCE,
        gtol=FIT_TOLERANCE,
        max_nfev=max_iterations,
    )
    jac = jacobian(fit.x)
    H, _, cost = _normal_equations(residuals(fit.x), jac)
    return fit.x, H, cost, bool(fit.success)
