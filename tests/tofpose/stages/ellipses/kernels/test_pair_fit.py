"""``kernels.pair_fit``: the compiled two-disc model and its Levenberg-Marquardt loop."""

import math

import numpy as np
from scipy.optimize import approx_fprime

from tests.tofpose.stages.ellipses.test_pair_split import BACKGROUND, _component, _discs
from tofpose.stages.ellipses import pair_fit as library
from tofpose.stages.ellipses.kernels.pair_fit import half_erfc, pair_model
from tofpose.stages.ellipses.pair_fit import fit_pair
from tofpose.stages.ellipses.reference import pair_fit as reference


def _reference_fit(img, pixels, start, background):
    """``fit_pair`` with the reference's fit (SciPy's bounded least_squares on the model,
    ``reference.pair_fit.fit_pair_lm``) in place of the compiled loop."""
    su, sv, values, p0, lower, upper = library._problem(img, pixels, start, background)
    p, normal, cost, converged = reference.fit_pair_lm(
        su,
        sv,
        values,
        p0,
        lower,
        upper,
        library.MAX_EVALUATIONS,
        library.CENTRE_TOLERANCE_PX,
        library.COST_TOLERANCE,
    )
    return library._result(p, normal, cost, len(values), lower, upper) if converged else None


def test_the_coverage_edge_is_erfc_within_its_stated_error():
    z = np.linspace(-6.0, 6.0, 4001)
    got = np.array([half_erfc(x, math.exp(-x * x)) for x in z])
    want = np.array([0.5 * math.erfc(x) for x in z])
    assert np.abs(got - want).max() <= 1.5e-7 / 2 + 1e-12


def test_the_model_is_the_numpy_model_and_its_jacobian_is_its_derivative():
    """The residuals against the reference's (``reference.pair_fit.pair_model``)."""
    rng = np.random.default_rng(3)
    su, sv = rng.uniform(10, 20, (40, 9)), rng.uniform(9, 14, (40, 9))
    values = rng.uniform(0, 2000, 40)
    p = np.array([13.0, 11.5, 18.0, 12.0, 1500.0, 1800.0, 2.1, 0.7, 100.0])
    jac = np.empty((40, 9))
    res = pair_model(p, su, sv, values, jac)
    want = reference.pair_model(p, su, sv, values, np.empty((40, 9)))
    np.testing.assert_allclose(res, want, atol=1e-3)
    numeric = np.array(
        [
            approx_fprime(
                p, lambda q, i=i: pair_model(q, su, sv, values, np.empty((40, 9)))[i], 1e-6
            )
            for i in range(40)
        ]
    )
    np.testing.assert_allclose(jac, numeric, atol=1e-3 * np.abs(numeric).max())


def test_the_compiled_fit_finds_the_reference_fit_and_the_truth():
    """Twelve random pairs (separation 3.5-6 px, radius 1.6-2.6 px, blur 0.4-1.2 px,
    gains within 30 %, pixel noise): the compiled fit's centres agree with SciPy's
    bounded least_squares on the same model within 1e-3 px, and both with the true
    centres within 0.1 px."""
    rng = np.random.default_rng(4)
    for _ in range(12):
        c1 = np.array([12.0, 11.0]) + rng.uniform(-0.5, 0.5, 2)
        angle = rng.uniform(0, np.pi)
        sep = rng.uniform(3.5, 6.0)
        centres = np.array([c1, c1 + sep * np.array([np.cos(angle), np.sin(angle)])])
        radius, blur = rng.uniform(1.6, 2.6), rng.uniform(0.4, 1.2)
        img = _discs(centres, radius, (1.0, rng.uniform(0.7, 1.3)), blur)
        img += rng.normal(0.0, 15.0, img.shape).astype(np.float32)
        comp = _component(img, BACKGROUND + 0.25 * (img.max() - BACKGROUND))
        start = centres + rng.uniform(-0.3, 0.3, (2, 2))
        got = fit_pair(img, comp.pixels, start, BACKGROUND)
        ref = _reference_fit(img, comp.pixels, start, BACKGROUND)
        assert got is not None and ref is not None
        np.testing.assert_allclose(got.centres_px, ref.centres_px, atol=1e-3)
        np.testing.assert_allclose(got.centres_px, centres, atol=0.1)
        assert abs(got.radius_px - ref.radius_px) < 1e-2


def test_a_pair_at_a_plate_edge_is_not_pulled_towards_the_plate():
    """Two discs (radius 1.6 px, 3.6 px apart, as markers 7 and 8 at 8 m) with a plate
    of +100 counts behind them ending 0.5 px right of the right disc's rim, and nothing
    beyond: the fitted centres are within 0.1 px of the truth (the fitted local level
    takes the step: 0.005 px here, 0.04-0.07 px with a plate three times as bright)."""
    centres = np.array([[12.3, 11.4], [15.9, 11.6]])
    img = _discs(centres, 1.6, (1.0, 1.0), 0.5)
    covered = (img - BACKGROUND) / 2000.0  # the discs' share of each pixel
    img[:, :18] += 100.0 * (1.0 - covered[:, :18])  # the plate, where the discs do not hide it
    img += np.random.default_rng(5).normal(0.0, 10.0, img.shape).astype(np.float32)
    comp = _component(img, BACKGROUND + 100.0 + 0.3 * (img.max() - BACKGROUND - 100.0))
    got = fit_pair(img, comp.pixels, centres + [[0.3, 0.0], [-0.3, 0.0]], BACKGROUND + 100.0)
    assert got is not None
    np.testing.assert_allclose(got.centres_px, centres, atol=0.1)
