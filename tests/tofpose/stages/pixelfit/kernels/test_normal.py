"""The compiled normal equations (``kernels.normal``) against the NumPy arithmetic they
fold (``fit._sigmas``, ``fit._residuals``, ``fit._jacobian``, ``fit.disc_blocks``), at
the iterations of a fit with every kind of parameter and row."""

from dataclasses import replace

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

    def spy(pb, state, images, extra_var, coverage_sigma, max_iterations, *tolerance):
        calls.append((pb, state, images, extra_var, coverage_sigma))
        return original(pb, state, images, extra_var, coverage_sigma, max_iterations, *tolerance)

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
    information and gradient, at the start state of every solve (and of the same solve
    with the plate's edge across the windows), after a step of every
    parameter (the range offsets 1 mm: their priors' rows then count), and with the
    gains tripled (censored pixels whose model is above full scale, weight 0). The
    information and gradients are compared in the parameters' own scale (``D J'J D``,
    ``D J'r`` with ``D = diag(J'J)^-1/2``), so that every entry counts, a prior's 0.04
    beside a pose entry's 1e7 too; to 1e-9."""
    calls = _solver_calls(monkeypatch, noise_options, clip)
    assert calls
    seen = dict.fromkeys(
        [
            "censored, model below full scale",
            "censored, model at or above it (weight 0)",
            "each disc's range error",
            "the rim's model error",
            "the offset's prior",
        ],
        False,
    )
    rng = np.random.default_rng(0)
    edged = []
    for pb, state, images, extra_var, coverage_sigma in calls:
        # the same problem with the plate's edge across every window: a part of each
        # pixel beyond the plate, at a level of its own
        p_count = pb.win.n_pixels
        plate = np.where(rng.random(p_count) < 0.3, rng.uniform(0.0, 1.0, p_count), 1.0)
        beyond = rng.uniform(0.0, 300.0, p_count) * (1.0 - plate)
        edge = replace(pb, plate_fraction=plate, beyond_counts=beyond)
        edged.append((edge, state, images, extra_var, coverage_sigma))
    for pb, state, images, extra_var, coverage_sigma in calls + edged:
        rim = None
        if np.any(coverage_sigma > 0):
            rim = fit._rim_sensitivity(pb, images, pb.predict(images, state), state)
        record = fit._fit_record(pb, rim, coverage_sigma)
        constants = fit._fit_constants(pb, extra_var)
        layout = pb.layout
        scale = np.r_[[1e-4] * 3, [0.05] * 3, np.ones(pb.n_params - 6)]  # rad, mm, counts
        if layout.offset_col >= 0:
            scale[layout.offset_col] = 1.0  # mm
        delta = rng.normal(0.0, 1.0, pb.n_params) * scale * pb.free
        bright = replace(state, gains=3.0 * state.gains)
        for s in (state, state.stepped(delta, pb.layout), bright):
            im, d_im = pb.images_with_derivatives(s.R, s.t_mm)
            info, grad, cost, sigma_gray, sigma_distance, k, blocks, block_grads = (
                normal.normal_equations(
                    fit._image_record(im, d_im), fit._nuisance_record(s), record, constants, True
                )
            )
            pred = pb.predict(im, s)
            sig = fit._sigmas(pb, pred, extra_var, rim, coverage_sigma)
            r = fit._residuals(pb, pred, sig, s)
            J = fit._jacobian(pb, s, im, pred, sig, d_im)
            ref_blocks, ref_grads = fit.disc_blocks(J, r, fit._row_owners(pb), len(pb.discs.ids))
            d = 1.0 / np.sqrt(np.diag(J.T @ J))
            for got, want in (
                (d[:, None] * info * d, d[:, None] * (J.T @ J) * d),
                (d * grad, d * (J.T @ r)),
                (d[:, None] * blocks * d, d[:, None] * ref_blocks * d),
                (d * block_grads, d * ref_grads),
                (cost, r @ r),
                (sigma_gray, sig.gray),
                (sigma_distance, sig.distance_mm),
                (k, sig.range_k_mm),
            ):
                np.testing.assert_allclose(
                    got, want, rtol=0, atol=1e-9 * max(np.abs(want).max(), 1)
                )
            trial = normal.trial_cost(
                im.coverage,
                im.phasor,
                im.plate_phasor,
                fit._nuisance_record(s),
                sig.gray,
                sig.distance_mm,
                record,
                constants,
            )
            assert trial == pytest.approx(r @ r, rel=1e-12)
            model_sat = pred.gray[pb.sat_rows]
            fs = pb.noise.full_scale_counts
            seen["censored, model below full scale"] |= bool(np.any(model_sat < fs))
            seen["censored, model at or above it (weight 0)"] |= bool(np.any(model_sat >= fs))
            seen["each disc's range error"] |= pb.disc_range_sigma_mm > 0
            seen["the rim's model error"] |= rim is not None
            seen["the offset's prior"] |= layout.offset_col >= 0 and bool(
                np.isfinite(pb.offset_sigma_mm)
            )
    if clip:
        assert all(seen.values()), seen
