"""The five-coefficient fit of a rational lens model recovers known truths."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tofpose.io.interop.distortion_fit import fit_five_coefficients

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 288.0], [0.0, 0.0, 1.0]])


def test_cancelling_rational_model_is_no_distortion():
    # (1 + a r^2) / (1 + a r^2) = 1: the rational model of an ideal lens
    fit = fit_five_coefficients(
        K, np.array([0.4, 0, 0, 0, 0, 0.4, 0, 0]), width=640, height=576, field_radius=1.0
    )
    assert_allclose(fit.dist, 0.0, atol=1e-6)
    assert fit.max_error_px < 1e-3


def test_five_coefficients_are_kept_exactly():
    d = np.array([-0.3, 0.1, 1e-4, -2e-4, -0.02, 0, 0, 0])
    fit = fit_five_coefficients(K, d, width=640, height=576, field_radius=1.0)
    assert fit.dist == tuple(d[:5])
    assert fit.max_error_px == 0.0


def test_no_rays_in_the_image_is_an_error():
    off_image = K + np.array([[0.0, 0.0, 5000.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="only 0 rays within radius 1.0"):
        fit_five_coefficients(off_image, np.zeros(8), width=640, height=576, field_radius=1.0)
    with pytest.raises(ValueError, match=r"dist8 \(8,\)"):
        fit_five_coefficients(K, np.zeros(5), width=640, height=576, field_radius=1.0)
