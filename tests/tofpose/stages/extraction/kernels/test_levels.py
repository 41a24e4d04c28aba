"""Frame levels and the distance clean-up against NumPy's own arithmetic."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.stages.extraction.kernels.levels import (
    _median_of_levels,
    clean_distance,
    frame_level_stats,
)


@pytest.mark.parametrize("kind", ["dark counts", "bright counts", "fractional", "odd"])
def test_counting_median_equals_numpy_median(kind):
    rng = np.random.default_rng(3)
    v = {
        "dark counts": rng.poisson(3.0, 8560),
        "bright counts": rng.integers(0, 4096, 8560),
        "fractional": rng.normal(200.0, 30.0, 8560),  # not counts: the partition path
        "odd": rng.poisson(50.0, 8561),
    }[kind].astype(np.float32)
    assert _median_of_levels(v) == float(np.median(v))
    dev = np.abs(v - np.float32(np.median(v)))  # half-integer deviations for even counts
    assert _median_of_levels(dev) == float(np.median(dev))


@pytest.mark.parametrize(
    "kind", ["counts", "half counts", "median between two levels", "fractional"]
)
def test_frame_level_stats_match_numpy(kind):
    """Background and MAD of the strided subsample as NumPy's medians give them, both
    from one folded histogram (counts, half counts), with the deviations counted
    separately (a median half-way between two half counts is a quarter count) or both
    by selection (fractional levels)."""
    rng = np.random.default_rng(0)
    g = rng.poisson(4.0, (240, 320)).astype(np.float32)
    if kind == "half counts":
        g += 0.5
    elif kind == "median between two levels":
        sub = g[::3, ::3]
        sub[...] = 4.0
        sub.flat[sub.size // 2 :] = 3.5  # an even count split between 3.5 and 4: 3.75
    elif kind == "fractional":
        g = rng.normal(40.0, 6.0, g.shape).astype(np.float32)
    g[100:110, 50:60] = 4095.0  # a saturated patch
    bg, mad, n_sat, _ = frame_level_stats(g, 3, 4095.0)
    sub = g[::3, ::3]
    assert bg == float(np.median(sub))
    assert mad == float(np.median(np.abs(sub - np.float32(bg))))
    assert n_sat == 100


def test_clean_distance_marks_invalid_pixels_nan():
    d = np.array([[1000.0, -5.0, 0.0], [np.inf, np.nan, 2500.5]])
    out = clean_distance(d)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(out), [[False, True, True], [True, True, False]])
    assert out[0, 0] == 1000.0 and out[1, 2] == np.float32(2500.5)


def test_threshold_mask_is_numpy_threshold_with_opencv_bounding_box():
    import cv2

    from tofpose.stages.extraction.kernels.levels import threshold_mask

    rng = np.random.default_rng(2)
    for trial in range(200):
        g = rng.gamma(2.0, 30.0, (60, 80)).astype(np.float32)
        threshold = float(rng.uniform(50.0, 400.0)) if trial % 5 else 1e9  # some empty
        mask, runs, n, box = threshold_mask(g, threshold)
        want = (g >= np.float32(threshold)).view(np.uint8)
        np.testing.assert_array_equal(mask, want)
        assert n == int(want.sum())
        assert tuple(box) == cv2.boundingRect(want)
        # the runs are the mask's maximal horizontal runs, in raster order
        from_runs = np.zeros_like(want)
        for r, first, end in runs:
            from_runs[r, first:end] = 1
            assert first == 0 or not want[r, first - 1]
            assert end == want.shape[1] or not want[r, end]
        np.testing.assert_array_equal(from_runs, want)
        assert np.all(np.diff(runs[:, 0] * 1000 + runs[:, 1]) > 0)
