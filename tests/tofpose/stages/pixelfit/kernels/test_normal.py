"""The compiled normal equations (``kernels.normal``) against the NumPy arithmetic they
fold (``fit._sigmas``, ``fit._residuals``, ``fit._jacobian``, ``fit.disc_blocks``), at
the iterations of a fit with every kind of parameter and row."""

import numpy as np
import pytest

from tests.tofpose.stages.pixelfit.test_fit import fit_with_every_parameter
from tofpose.stages.pixelfit import fit
from tofpose.stages.pixelfit.kernels import normal


def _solver_calls(monkeypatch, noise_options, clip):
    """Every ``fit._levenberg_marquardt`` call (its arguments) of
    ``fit_with_every_parameter(noise_options, clip=clip)``."""
    calls = []
    original = fit._levenberg_marquardt

    def spy(pb, state, images, extra_var, coverage_sigma, max_iterations):
        calls.append((pb, state, images, extra_var, coverage_sigma))
        return original(pb, state, images, extra_var, coverage_sigma, max_iterations)

    monkeypatch.setattr(fit, "_levenberg_marquardt", spy)
    fit_with_every_parameter(noise_options, clip=clip)
    return calls


@pytest.mark.parametrize(
    ("noise_options", "clip"),
    [
        # rim model error and each disc's range error given, censored pixels
        ({"disc_range_sigma_mm": 3.0, "coverage_sigma": 0.02}, True),
        # the range constant measured on the residuals (a median in the kernel)
        ({"range_k_mm": None}, False),
    ],
)
def test_normal_equations_equal_the_numpy_jacobians(monkeypatch, noise_options, clip):
    """Information, gradient and cost, the sigmas, and each disc's share of the
    information and gradient: to 1e-9 of their largest, at the start state and after a
    step of every parameter."""
    calls = _solver_calls(monkeypatch, noise_options, clip)
    assert calls
    checked = set()
    for pb, state, images, extra_var, coverage_sigma in calls:
        rim = None
        if np.any(coverage_sigma > 0):
            rim = fit._rim_sensitivity(pb, images, pb.predict(images, state), state)
        record = fit._fit_record(pb, rim, coverage_sigma)
        constants = fit._fit_constants(pb, extra_var)
        delta = np.random.default_rng(0).normal(0.0, 1e-3, pb.n_params) * pb.free
        for s in (state, state.stepped(delta, pb.layout)):
            im, d_im = pb.images_with_derivatives(s.R, s.t_mm)
            info, grad, cost, sigma_gray, sigma_distance, k, blocks, block_grads = (
                normal.normal_equations(
                    *fit._image_arrays(im, d_im), *fit._state_arrays(s), record, constants, True
                )
            )
            pred = pb.predict(im, s)
            sig = fit._sigmas(pb, pred, extra_var, rim, coverage_sigma)
            r = fit._residuals(pb, pred, sig, s)
            J = fit._jacobian(pb, s, im, pred, sig, d_im)
            ref_blocks, ref_grads = fit.disc_blocks(J, r, fit._row_owners(pb), len(pb.discs.ids))
            for got, want in (
                (info, J.T @ J),
                (grad, J.T @ r),
                (cost, r @ r),
                (sigma_gray, sig.gray),
                (sigma_distance, sig.distance_mm),
                (k, sig.range_k_mm),
                (blocks, ref_blocks),
                (block_grads, ref_grads),
            ):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
            trial = normal.trial_cost(
                im.coverage,
                im.phasor,
                im.plate_phasor,
                *fit._state_arrays(s),
                sig.gray,
                sig.distance_mm,
                record,
                constants,
            )
            assert trial == pytest.approx(r @ r, rel=1e-12)
            checked.add((len(pb.sat_rows) > 0, pb.disc_range_sigma_mm > 0, rim is not None))
    if "coverage_sigma" in noise_options:
        # censored rows, each disc's range error and the rim's model error all seen
        assert (True, True, True) in checked
