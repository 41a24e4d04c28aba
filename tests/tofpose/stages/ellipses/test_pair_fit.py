"""``pair_fit``: two blurred discs fitted to the pixels of a merged pair."""

import numpy as np
from scipy.optimize import approx_fprime

from tests.tofpose.stages.ellipses.test_pair_split import BACKGROUND, _component, _discs
from tofpose.stages.ellipses.pair_fit import fit_pair
from tofpose.stages.ellipses.reference.pair_fit import pair_model


def test_the_analytic_jacobian_is_the_model_derivative():
    rng = np.random.default_rng(1)
    su, sv = rng.uniform(10, 20, (30, 9)), rng.uniform(9, 14, (30, 9))
    values = np.zeros(30)
    p = np.array([13.0, 11.5, 18.0, 12.0, 1500.0, 1800.0, 2.1, 0.7, 100.0])
    jac = np.empty((30, 9))
    pair_model(p, su, sv, values, jac)  # the reference's model and analytic Jacobian
    numeric = np.array(
        [
            approx_fprime(
                p, lambda q, i=i: pair_model(q, su, sv, values, np.empty((30, 9)))[i], 1e-6
            )
            for i in range(30)
        ]
    )
    np.testing.assert_allclose(jac, numeric, atol=1e-4 * np.abs(numeric).max())


def test_the_fit_recovers_the_centres_radius_and_blur_of_a_pair():
    """Known discs (radius 2.15 px, 4.9 px apart, blur 0.8 px, gains 1 and 1.3, pixel
    noise): centres within 0.05 px, radius within 0.2 px, blur within 0.2 px, and the
    centres' reported sigma at most the error's scale (not a claim of 0.001 px)."""
    centres = np.array([[13.2, 11.6], [18.1, 11.9]])
    img = _discs(centres, 2.15, (1.0, 1.3), 0.8)
    img += np.random.default_rng(2).normal(0.0, 20.0, img.shape).astype(np.float32)
    comp = _component(img, BACKGROUND + 0.25 * (img.max() - BACKGROUND))
    fit = fit_pair(img, comp.pixels, centres + [[0.3, -0.2], [-0.3, 0.2]], BACKGROUND)
    assert fit is not None
    np.testing.assert_allclose(fit.centres_px, centres, atol=0.05)
    assert abs(fit.radius_px - 2.15) < 0.2 and abs(fit.blur_px - 0.8) < 0.2
    assert np.all(fit.sigma_px > 0.001) and np.all(fit.sigma_px < 0.05)
