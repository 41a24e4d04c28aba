"""Reference rate and latency fit against a known delay (tofpose.lab.dynamics)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.lab.dynamics import angular_rate_deg_s, fit_latency, reference_spline

R_FACING = np.diag([1.0, -1.0, -1.0])
AMPLITUDE_DEG, PERIOD_S = 5.0, 4.0


def _yaw_deg(t_s):
    return AMPLITUDE_DEG * np.sin(2 * np.pi * np.asarray(t_s) / PERIOD_S)


def _reference(t_s):
    """R_camera_target of a camera yawing about its own y axis by the sine."""
    yaw = -np.atleast_1d(_yaw_deg(t_s))[:, None]
    return Rotation.from_euler("y", yaw, degrees=True).as_matrix() @ R_FACING


def test_reference_rate_is_the_camera_frame_rate_of_the_sine():
    t = np.linspace(0.0, 8.0, 81)
    spline = reference_spline(t, _reference(t))
    at = np.linspace(1.0, 7.0, 13)
    w = angular_rate_deg_s(spline, at)
    want_y = -AMPLITUDE_DEG * 2 * np.pi / PERIOD_S * np.cos(2 * np.pi * at / PERIOD_S)
    np.testing.assert_allclose(w[:, 1], want_y, atol=0.01)
    np.testing.assert_allclose(w[:, [0, 2]], 0.0, atol=1e-6)


def _measured(delay_s, noise_deg, rng, *, rho=0.0, rate_hz=10.0, offset_deg=(0.1, -0.2, 0.05)):
    t = np.arange(0.0, 12.0, 1 / rate_hz) + rng.uniform(0, 0.01)
    n = len(t)
    e = np.zeros((n, 3))
    white = rng.normal(0.0, noise_deg, (n, 3))
    for k in range(n):  # AR(1) noise of the same marginal sigma
        e[k] = white[k] if k == 0 else rho * e[k - 1] + np.sqrt(1 - rho**2) * white[k]
    R = _reference(t - delay_s) @ Rotation.from_rotvec(np.radians(e + offset_deg)).as_matrix()
    return t, R


@pytest.mark.parametrize("delay_s", [0.0, 0.037, 0.120])
def test_a_programmed_delay_is_found_within_its_sigma(delay_s):
    rng = np.random.default_rng(3)
    t, R = _measured(delay_s, 0.05, rng)
    ref_t = np.arange(-1.0, 13.0, 0.05)
    fit = fit_latency(t, R, ref_t, _reference(ref_t))
    assert abs(fit.delay_s - delay_s) < 3 * fit.sigma_s
    # the sigma is what the noise allows: 0.05 deg over ~120 frames at <= 7.9 deg/s
    assert 1e-4 < fit.sigma_s < 5e-3
    np.testing.assert_allclose(fit.offset_deg, (0.1, -0.2, 0.05), atol=0.03)
    assert fit.peak_rate_deg_s == pytest.approx(7.85, abs=0.05)


@pytest.mark.parametrize("rho", [0.0, 0.7])
def test_the_delay_sigma_is_honest_also_for_correlated_errors(rho):
    """Over many draws the standardised error has a standard deviation near 1: without
    the autocorrelation inflation, rho = 0.7 would give ~2.4."""
    rng = np.random.default_rng(11)
    ref_t = np.arange(-1.0, 13.0, 0.05)
    R_ref = _reference(ref_t)
    z = []
    for _ in range(60):
        t, R = _measured(0.05, 0.08, rng, rho=rho)
        fit = fit_latency(t, R, ref_t, R_ref)
        z.append((fit.delay_s - 0.05) / fit.sigma_s)
    assert 0.6 < np.std(z) < 1.4, np.std(z)
    assert abs(np.mean(z)) < 0.5


def test_a_reference_at_rest_shows_no_delay():
    t = np.arange(0.0, 5.0, 0.1)
    R = np.repeat(R_FACING[None], len(t), axis=0)
    ref_t = np.arange(-1.0, 6.0, 0.1)
    with pytest.raises(ValueError, match="does not move"):
        fit_latency(t, R, ref_t, np.repeat(R_FACING[None], len(ref_t), axis=0))


def test_frames_outside_the_reference_are_named():
    t = np.arange(0.0, 1.0, 0.1)
    ref_t = np.arange(0.0, 1.0, 0.1)
    with pytest.raises(ValueError, match="within the reference span"):
        fit_latency(t, _reference(t), ref_t, _reference(ref_t))
