"""Component table, medians and the nLoG against OpenCV (the gates as a whole against
``tofpose.stages.extraction.reference.extraction``:
tests/tofpose/stages/extraction/reference/test_extraction.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.config import ExtractionConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.stages.extraction.extraction import check_frame, find_candidate_blobs, frame_levels
from tofpose.stages.extraction.kernels.components import (
    component_median_ranges,
    component_table,
    median_of_finite,
    run_labels,
)
from tofpose.stages.extraction.kernels.gates import nlog_patch
from tofpose.stages.extraction.kernels.levels import threshold_mask
from tofpose.stages.extraction.reference.extraction import nlog_response


def _table(mask, gray):
    """The component table of a mask as find_candidate_blobs builds it: its runs, their
    labels, the table."""
    runs = threshold_mask(mask.astype(np.float32), 0.5)[1]
    labels, n = run_labels(runs)
    return component_table(runs, labels, n, gray)


def _assert_is_opencvs(table, mask, gray):
    """The table holds OpenCV's components of the whole mask, numbered as OpenCV does."""
    area, bbox, peak, starts, flat, run_order, run_starts = table
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    assert len(area) == n
    np.testing.assert_array_equal(area[1:], stats[1:, cv2.CC_STAT_AREA])
    np.testing.assert_array_equal(bbox[1:], stats[1:, :4])
    runs = threshold_mask(mask.astype(np.float32), 0.5)[1]
    for k in range(1, n):
        np.testing.assert_array_equal(
            flat[starts[k] : starts[k + 1]], np.flatnonzero(labels.ravel() == k)
        )
        assert peak[k] == gray[labels == k].max()
        own = runs[run_order[run_starts[k] : run_starts[k + 1]]]
        assert all((labels[r, a:b] == k).all() for r, a, b in own)
        assert sum(b - a for _, a, b in own) == area[k]


def test_component_table_equals_opencv_stats():
    rng = np.random.default_rng(1)
    mask = (rng.random((60, 80)) > 0.8).astype(np.uint8)
    gray = rng.random((60, 80)).astype(np.float32)
    _assert_is_opencvs(_table(mask, gray), mask, gray)


def test_run_labels_number_the_components_as_opencv_does():
    """Random sets of every density and size, odd and even edges: the same label image
    as cv2.connectedComponents (8-connectivity), including its numbering."""
    rng = np.random.default_rng(5)
    for trial in range(1500):
        h, w = (int(v) for v in rng.integers(1, 70, 2))
        mask = (rng.random((h, w)) > rng.uniform(0.2, 0.95)).astype(np.uint8)
        if trial % 3 == 0:  # larger blobs with holes and bays
            mask = cv2.dilate(mask, np.ones((2, 2), np.uint8))
        runs = threshold_mask(mask.astype(np.float32), 0.5)[1]
        labels, n = run_labels(runs)
        n_cv, want = cv2.connectedComponents(mask, connectivity=8)
        image = np.zeros((h, w), np.int32)
        for (r, a, b), k in zip(runs, labels, strict=True):
            image[r, a:b] = k
        assert n == n_cv
        np.testing.assert_array_equal(image, want)


def test_a_frames_active_set_is_labelled_as_opencv_labels_it():
    cam, cfg = CameraModel(), ExtractionConfig()
    for distance_mm in (700.0, 3000.0, 9000.0):
        frame = render(facing_pose(distance_mm, 3, -4, 12), seed=2)
        g, d = check_frame(cam, frame.gray, frame.distance_mm)
        found = find_candidate_blobs(
            g, d, cam, paper_target().diameters_mm, cfg, frame_levels(g, cfg)
        )
        _assert_is_opencvs(_table(found.active_mask, g), found.active_mask, g)


def test_median_of_finite_is_numpy_median_without_nans():
    rng = np.random.default_rng(2)
    for n in (1, 2, 7, 100):
        v = rng.normal(1000, 5, n).astype(np.float32)
        v[::3] = np.nan
        finite = v[np.isfinite(v)]
        want = float(np.median(finite)) if len(finite) else np.nan
        assert median_of_finite(v) == pytest.approx(want, nan_ok=True, abs=0)
    flat = np.arange(6, dtype=np.int64)
    d = np.array([1.0, np.nan, 3.0, np.nan, np.nan, np.nan], np.float32)
    med = component_median_ranges(flat, np.array([0, 0, 3, 6]), d, np.array([1, 2]))
    assert med[0] == 2.0 and np.isnan(med[1])


@pytest.mark.parametrize("sigma", [0.7, 2.0, 6.5])
def test_nlog_patch_matches_opencv(sigma):
    rng = np.random.default_rng(4)
    patch = np.zeros((30, 26), np.float32)
    patch[5:24, 4:21] = rng.uniform(100, 900, (19, 17))
    want = nlog_response(patch, sigma)
    # float32 rounding of the smoothed values (~1e-4 counts) is amplified by the
    # Laplacian's differences and the sigma^2 normalisation: compare at 1e-5 of the peak
    np.testing.assert_allclose(
        nlog_patch(patch, sigma, True), want, rtol=0, atol=1e-5 * np.abs(want).max()
    )
