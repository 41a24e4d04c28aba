"""The compiled range correction against the model's definition,
``RangeCorrection.error_mm``: each blob's range less the median error over its pixels."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.calibration.range import RangeCorrection
from tofpose.stages.persistence.kernels.range_correction import corrected_ranges

H, W = 24, 32


def _blobs(rng, n):
    """n blobs of 1-40 distinct pixels each (flat indices), with ranges (one NaN)."""
    sizes = rng.integers(1, 41, n)
    pixels = [rng.choice(H * W, s, replace=False).astype(np.int64) for s in sizes]
    rho = rng.uniform(600.0, 9000.0, n)
    rho[n // 2] = np.nan
    return pixels, rho


@pytest.mark.parametrize("with_offsets", [True, False], ids=["pixel offsets", "none"])
def test_corrected_ranges_subtract_the_median_modelled_error(with_offsets):
    rng = np.random.default_rng(3)
    model = RangeCorrection(
        25000.0,
        offset_mm=-4.0,
        harmonics_mm=((3.0, -2.0), (0.7, 0.4), (0.1, -0.2)),
        amplitude_mm_per_decade=2.5,
        amplitude_reference_counts=150.0,
        pixel_offsets_mm=rng.normal(0.0, 3.0, (H, W)) if with_offsets else None,
    )
    gray = rng.uniform(0.0, 4000.0, (H, W)).astype(np.float32)
    gray[0, :5] = 0.0  # amplitudes clipped at 1e-3 by the model
    pixels, rho = _blobs(rng, 9)
    pixels[0] = np.arange(5, dtype=np.int64)
    starts = np.r_[0, np.cumsum([len(p) for p in pixels])].astype(np.int64)
    got = corrected_ranges(rho, np.concatenate(pixels), starts, gray, *model.kernel_arguments())
    for j, p in enumerate(pixels):
        if not np.isfinite(rho[j]):
            assert np.isnan(got[j])
            continue
        err = model.error_mm(np.full(len(p), rho[j]), gray.ravel()[p], p if with_offsets else None)
        assert got[j] == pytest.approx(rho[j] - np.median(err), abs=1e-9)
    # the correction is not nothing: the model's errors are millimetres here
    finite = np.isfinite(rho)
    assert np.median(np.abs(got[finite] - rho[finite])) > 1.0
