"""The reference statement of tracking mode's windows and window search
(``tofpose.stages.tracking.reference.tracking``) against the compiled one
(``tofpose.stages.tracking.kernels.tracking``)
on rendered frames at 0.7-8 m, with and without lens distortion, and on random speckle;
and against known truth on drawn discs.

Equality: catalog indices, window bounds, statuses, boxes, peaks and pixel lists exact
(the components' numbering too); predicted centres and diameters to 1e-9 px (OpenCV's
projection against the compiled one) and the Eq. 19 centroids to 1e-9 px (the weighted
sums in another order)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.records import camera_record, catalog_record
from tofpose.stages.tracking import constants as codes
from tofpose.stages.tracking.kernels import tracking as kernel
from tofpose.stages.tracking.reference import tracking as reference

DISTORTED = CameraModel(dist=(-0.02, 0.008, 0.0004, -0.0003, 0.0))
CAT = paper_target()
DISTANCES = (700.0, 1500.0, 3000.0, 5000.0, 8000.0)


def _windows(module, cam, T, margin_px=4.0, min_diameter_px=1.0):
    return module.camera_windows(
        catalog_record(CAT), T.R, T.t_mm, camera_record(cam), margin_px, min_diameter_px
    )


@cache
def _frame(distance_mm, distorted):
    """(camera, true pose, gray) of the paper target rendered at ``distance_mm``."""
    cam = DISTORTED if distorted else CameraModel()
    T = facing_pose(distance_mm, 3, -5, 12, offset_mm=(-60.0, 40.0))
    return cam, T, render(T, seed=int(distance_mm), camera=cam).gray


def _assert_same_search(got, want):
    for k in (0, 1, 2, 4, 5):  # status, bbox, peak, starts, flat
        np.testing.assert_array_equal(got[k], want[k])
    np.testing.assert_allclose(got[3], want[3], atol=1e-9, rtol=0)  # NaN where not found


@pytest.mark.parametrize("distorted", [False, True])
@pytest.mark.parametrize("distance_mm", DISTANCES)
def test_camera_windows_equal_the_kernel(distance_mm, distorted):
    """The true pose and poses a few degrees and centimetres off, margins 2-8 px."""
    cam, T, _ = _frame(distance_mm, distorted)
    rng = np.random.default_rng(int(distance_mm))
    for margin in (2.0, 4.0, 8.0):
        for _ in range(5):
            pose = facing_pose(
                distance_mm + rng.uniform(-100, 100),
                *rng.uniform(-8, 8, 3),
                offset_mm=rng.uniform(-300, 300, 2),
            )
            want = _windows(kernel, cam, pose, margin)
            got = _windows(reference, cam, pose, margin)
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
            np.testing.assert_allclose(got[2], want[2], atol=1e-9, rtol=0)
            np.testing.assert_allclose(got[3], want[3], atol=1e-9, rtol=0)
            assert got[1].dtype == got[0].dtype == np.int64


@pytest.mark.parametrize("distorted", [False, True])
@pytest.mark.parametrize("distance_mm", DISTANCES)
def test_search_windows_equals_the_kernel_on_rendered_frames(distance_mm, distorted):
    """Windows predicted from the true pose and from poses off by up to ~2 deg and 2 cm
    (some components reach their window's edge), thresholds from a tenth to a half of
    the peak."""
    cam, T, gray = _frame(distance_mm, distorted)
    rng = np.random.default_rng(1 + int(distance_mm))
    background = float(np.median(gray))
    statuses = set()
    for fraction in (0.1, 0.3, 0.5):
        threshold = np.float32(background + fraction * (gray.max() - background))
        for shift in range(4):
            pose = (
                T
                if shift == 0
                else facing_pose(
                    distance_mm,
                    3 + rng.normal(0, 1),
                    -5 + rng.normal(0, 1),
                    12 + rng.normal(0, 1),
                    offset_mm=(-60.0 + rng.normal(0, 10), 40.0 + rng.normal(0, 10)),
                )
            )
            idx, bounds, uv, d_px = _windows(kernel, cam, pose, 3.0)
            assert len(idx) >= (2 if distance_mm < 1000 else 6)  # 0.7 m: most leave the image
            want = kernel.search_windows(gray, bounds, uv, d_px, threshold, background)
            _assert_same_search(
                reference.search_windows(gray, bounds, uv, d_px, threshold, background), want
            )
            assert kernel.any_shared(want[5], want[4], want[1]) == reference.any_shared(
                want[5], want[4], want[1]
            )
            statuses.update(want[0].tolist())
    assert codes.FOUND in statuses


def test_search_windows_equals_the_kernel_on_random_speckle():
    """Many windows over frames of random speckle (5-50 % of pixels bright) and one in a
    dark corner, a float threshold and a float32 one: every status occurs and every
    output agrees."""
    rng = np.random.default_rng(3)
    statuses = set()
    for _ in range(60):
        gray = rng.uniform(0, 50, (70, 90)).astype(np.float32)
        gray[rng.random(gray.shape) < rng.uniform(0.05, 0.5)] = rng.uniform(500, 900)
        u0, v0 = rng.integers(0, 60, 8), rng.integers(0, 40, 8)
        size = rng.integers(2, 30, (8, 2))
        bounds = np.column_stack(
            (u0, np.minimum(u0 + size[:, 0], 90), v0, np.minimum(v0 + size[:, 1], 70))
        ).astype(np.int64)
        gray[:12, :12] = 5.0  # a dark corner: window 0 finds nothing there
        bounds[0] = (0, 12, 0, 12)
        centres = np.column_stack((bounds[:, :2].mean(axis=1), bounds[:, 2:].mean(axis=1)))
        centres += rng.normal(0, 3, centres.shape)
        diameters = rng.uniform(0.5, 8.0, 8)
        for threshold in (np.float32(400.0), 300.1):
            want = kernel.search_windows(gray, bounds, centres, diameters, threshold, 10.0)
            got = reference.search_windows(gray, bounds, centres, diameters, threshold, 10.0)
            _assert_same_search(got, want)
            statuses.update(want[0].tolist())
    assert statuses == {codes.FOUND, codes.NOT_FOUND, codes.NO_SIZE, codes.AT_EDGE}


def test_the_window_components_as_runs_equal_the_kernel():
    """``_window_runs``: the union-find's runs, numbering, areas, sums and boxes against
    OpenCV's labelling, on speckle dense enough to join into long diagonal chains."""
    rng = np.random.default_rng(6)
    for _ in range(200):
        gray = rng.uniform(0, 50, (40, 50)).astype(np.float32)
        gray[rng.random(gray.shape) < rng.uniform(0.05, 0.6)] = 900.0
        u0, v0 = (int(v) for v in rng.integers(0, 10, 2))
        want = kernel._window_runs(gray, u0, 50, v0, 40, np.float32(400.0))
        got = reference._window_runs(gray, u0, 50, v0, 40, np.float32(400.0))
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)


def test_any_shared_equals_the_kernel():
    rng = np.random.default_rng(7)
    answers = set()
    for _ in range(300):
        lists = [np.unique(rng.integers(0, 400, rng.integers(1, 30))) for _ in range(3)]
        flat = np.concatenate(lists).astype(np.int64)
        starts = np.cumsum([0] + [len(v) for v in lists]).astype(np.int64)
        bbox = np.array(
            [
                [(v % 20).min(), (v // 20).min(), np.ptp(v % 20) + 1, np.ptp(v // 20) + 1]
                for v in lists
            ],
            np.int64,
        )
        want = kernel.any_shared(flat, starts, bbox)
        assert reference.any_shared(flat, starts, bbox) == want
        answers.add(bool(want))
    assert answers == {False, True}


def test_a_drawn_disc_is_found_and_one_at_the_edge_is_reported():
    """A 7 px disc (uniform, symmetric about its integer centre) in a window around it:
    found, its pixels exactly the drawn ones, its box the disc's and its centroid the
    centre; the same disc in a window whose border it touches: AT_EDGE; an empty window:
    NOT_FOUND; a window expecting a disc of 40 px: NO_SIZE."""
    gray = np.full((60, 80), 20.0, np.float32)
    v, u = np.mgrid[0:60, 0:80]
    disc = (u - 30) ** 2 + (v - 25) ** 2 <= 3.5**2
    gray[disc] = 1500.0
    bounds = np.array([[22, 39, 17, 34], [27, 45, 15, 35], [50, 70, 40, 55], [22, 39, 17, 34]])
    centres = np.array([[30.5, 24.6], [36.0, 25.0], [60.0, 47.0], [30.0, 25.0]])
    diameters = np.array([7.0, 7.0, 7.0, 40.0])
    status, bbox, peak, centroid, starts, flat = reference.search_windows(
        gray, bounds, centres, diameters, np.float32(700.0), 20.0
    )
    assert status.tolist() == [
        codes.FOUND,
        codes.AT_EDGE,
        codes.NOT_FOUND,
        codes.NO_SIZE,
    ]
    np.testing.assert_array_equal(flat[starts[0] : starts[1]], np.flatnonzero(disc))
    assert starts.tolist() == [0, disc.sum()] + [disc.sum()] * 3
    assert bbox[0].tolist() == [27, 22, 7, 7] and peak[0] == 1500.0
    np.testing.assert_allclose(centroid[0], [30.0, 25.0], atol=1e-12)
    assert np.isnan(centroid[1:]).all()


def test_windows_sit_on_the_projected_reflectors():
    """At 3 m every reflector gets a window holding its projection with the margin on
    each side; at 8 m markers 7 and 8 (closer than 2 px rim to rim) get none; with the
    target behind the camera, no window at all."""
    for cam in (CameraModel(), DISTORTED):
        T = facing_pose(3000.0, 2, -3, 10)
        idx, bounds, uv, d_px = _windows(reference, cam, T)
        assert idx.tolist() == list(range(8))
        np.testing.assert_allclose(uv, cam.project(T.apply(CAT.positions_mm)), atol=1e-9)
        np.testing.assert_allclose(
            d_px, cam.fx * CAT.diameters_mm / T.apply(CAT.positions_mm)[:, 2]
        )
        assert np.all(bounds[:, 0] <= uv[:, 0] - d_px / 2 - 4.0)
        assert np.all(bounds[:, 1] > uv[:, 0] + d_px / 2 + 4.0)
        assert np.all(bounds[:, 2] <= uv[:, 1] - d_px / 2 - 4.0)
        assert np.all(bounds[:, 3] > uv[:, 1] + d_px / 2 + 4.0)
        far = _windows(reference, cam, facing_pose(8000.0))[0]
        assert far.tolist() == [0, 1, 2, 3, 4, 5]
        behind = _windows(reference, cam, facing_pose(-3000.0))
        assert len(behind[0]) == 0 and behind[1].shape == (0, 4)
