"""The reference measurement sigmas and Eq. 21's weights against known truth."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.stages.extraction.reference import sigmas as reference
from tofpose.stages.extraction.uncertainty import SigmaFloors, kernel_constants

CONSTANTS = kernel_constants(SigmaFloors(0.03, 1.0))


def test_a_single_pixel_is_located_no_better_than_uniform_over_the_pixel():
    gray = np.full((5, 5), 100.0)
    gray[2, 2] = 4000.0
    sigma = reference.centroid_sigma_px(
        gray, np.array([12]), np.array([2.0, 2.0]), 100.0, False, CONSTANTS
    )
    # no shot-noise lever arm at the centroid itself: the floor and the grid's 1/sqrt(12)
    assert sigma == pytest.approx(np.hypot(0.03, 1 / np.sqrt(12)), rel=1e-12)


def test_the_pooled_range_model_measures_the_noise_a_frame_was_drawn_with():
    """Blobs of 60 pixels whose ranges scatter as k sqrt(G) / A with k = 200: the pooled
    k recovers it, and each blob's sigma is k unit * 1.2533 / sqrt(n)."""
    rng = np.random.default_rng(0)
    h, w = 40, 60
    gray = np.full((h, w), 500.0)
    dist = np.full((h, w), np.nan, np.float32)
    blobs = [np.arange(j * 600, j * 600 + 60) for j in range(4)]
    k_true, bg = 200.0, 100.0
    for j, b in enumerate(blobs):
        gray.reshape(-1)[b] = 400.0 + 300.0 * j
        unit = np.sqrt(400.0 + 300.0 * j) / (300.0 + 300.0 * j)
        dist.reshape(-1)[b] = 3000.0 + rng.normal(0.0, k_true * unit, 60)
    got = reference.range_sigmas_mm(gray, dist, blobs, bg, CONSTANTS)
    units = np.sqrt(400.0 + 300.0 * np.arange(4)) / (300.0 + 300.0 * np.arange(4))
    np.testing.assert_allclose(got, k_true * units * 1.2533 / np.sqrt(60), rtol=0.35)


def test_without_any_pooled_blob_a_rangeless_blob_gets_the_uncalibrated_sigma():
    gray = np.full((4, 4), 300.0)
    dist = np.full((4, 4), np.nan, np.float32)
    got = reference.range_sigmas_mm(gray, dist, [np.array([0, 1])], 50.0, CONSTANTS)
    assert got.tolist() == [CONSTANTS.uncalibrated_range_sigma_mm]


def test_eq_21_weights_are_the_inverse_point_variances():
    w = reference.weights(np.array([3000.0]), np.array([4.0]), np.array([0.1]), 300.0)
    assert w[0] == pytest.approx(1.0 / (16.0 + 1.0))
