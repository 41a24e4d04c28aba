"""The compiled two-centre split against ``tofpose.stages.ellipses.reference.two_centres``."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.stages.ellipses.kernels.two_centres import (
    SPLIT_OK,
    SPLIT_ROUND,
    two_centre_split,
)
from tofpose.stages.ellipses.reference.two_centres import two_centre_split as reference_split


@pytest.mark.parametrize("seed", range(12))
def test_two_centre_split_equals_the_reference_on_random_pairs(seed):
    """Two blurred discs 2.5-5 px apart in a random direction, noisy weights: the same
    halves and centres (up to which half is called first: the axis' sign is free)."""
    rng = np.random.default_rng(seed)
    c0 = rng.uniform(20, 40, 2)
    angle = rng.uniform(0, np.pi)
    c1 = c0 + rng.uniform(2.5, 5.0) * np.array([np.cos(angle), np.sin(angle)])
    v, u = np.mgrid[0:60, 0:60]
    img = sum(np.exp(-((u - c[0]) ** 2 + (v - c[1]) ** 2) / (2 * 1.2**2)) for c in (c0, c1))
    img = img * 500 + rng.normal(0, 5, img.shape)
    keep = img > 120
    rows, cols = np.nonzero(keep)
    weight = img[keep] - 20.0
    near, centres, status = two_centre_split(cols.astype(float), rows.astype(float), weight, 8)
    ref = reference_split(cols.astype(float), rows.astype(float), weight, 8)
    assert status == SPLIT_OK and ref is not None
    ref_near, ref_centres = ref
    if np.abs(centres[0] - ref_centres[0]).max() > 1e-6:  # the halves in the other order
        ref_near, ref_centres = 1 - ref_near, ref_centres[::-1]
    np.testing.assert_array_equal(near, ref_near)
    np.testing.assert_allclose(centres, ref_centres, atol=1e-9)
    # and they are the discs' centres to a fraction of a pixel
    truth = np.array([c0, c1]) if np.linalg.norm(centres[0] - c0) < 1.5 else np.array([c1, c0])
    assert np.abs(centres - truth).max() < 0.5


def test_a_round_spot_is_not_split():
    v, u = np.mgrid[0:30, 0:30]
    img = np.exp(-((u - 15.2) ** 2 + (v - 14.7) ** 2) / (2 * 1.5**2)) * 500
    rows, cols = np.nonzero(img > 50)
    w = img[img > 50]
    assert two_centre_split(cols.astype(float), rows.astype(float), w, 8)[2] == SPLIT_ROUND
    assert reference_split(cols.astype(float), rows.astype(float), w, 8) is None
