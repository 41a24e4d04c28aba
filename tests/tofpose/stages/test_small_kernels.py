"""Ellipse residual, perspective offsets and blob pixel statistics against NumPy and
``tofpose.reference``."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.stages.ellipses.kernels.ellipses import blob_mask, ellipse_rms_px
from tofpose.stages.extraction.kernels.perspective import disc_centre_offsets
from tofpose.stages.extraction.kernels.sigmas import blob_pixel_stats
from tofpose.stages.pose.reference.solve import disc_centre_offsets as ref_offsets


def test_ellipse_rms_is_zero_on_the_ellipse_and_the_radial_gap_off_it():
    th = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    a, b, ang = 20.0, 10.0, np.radians(30)
    pts = np.column_stack((a / 2 * np.cos(th), b / 2 * np.sin(th)))
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    pts = pts @ rot.T + [5.0, 7.0]
    assert ellipse_rms_px(5.0, 7.0, a, b, 30.0, pts) < 1e-12
    circle = np.column_stack((np.cos(th), np.sin(th))) * 6.0
    assert ellipse_rms_px(0.0, 0.0, 10.0, 10.0, 0.0, circle) == pytest.approx(1.0)


def test_blob_mask_places_pixels_in_the_padded_box():
    m = blob_mask(np.array([2 * 10 + 3, 3 * 10 + 4]), 3, 2, 2, 2, 10)
    assert m.shape == (4, 4) and m[1, 1] == 1 and m[2, 2] == 1 and m.sum() == 2


def test_perspective_offsets_vanish_face_on_and_match_the_conic_when_tilted():
    cam = CameraModel()
    centres = np.array([[0.0, 0.0, 1000.0], [300.0, -100.0, 1000.0]])
    radii = np.array([40.0, 17.5])
    face_on = disc_centre_offsets(cam.K, centres, np.array([0.0, 0.0, -1.0]), radii)
    assert np.abs(face_on).max() < 1e-9  # a fronto-parallel circle images as a circle
    tilted = np.array([0.3, -0.2, -1.0])
    got = disc_centre_offsets(cam.K, centres, tilted, radii)
    np.testing.assert_allclose(got, ref_offsets(cam.K, centres, tilted, radii), atol=1e-12)
    assert np.abs(got[0]).max() > 0.01


def test_perspective_offsets_match_the_conic_over_ranges_and_tilts():
    """The kernel's pole of the line at infinity against the conic's inverse, from 0.4 to
    12 m and tilts up to ~56 deg (offsets up to a few px)."""
    cam = CameraModel()
    rng = np.random.default_rng(3)
    for _ in range(300):
        z = rng.uniform(400.0, 12000.0)
        centres = np.column_stack(
            (
                rng.uniform(-0.4, 0.4, 8) * z,
                rng.uniform(-0.3, 0.3, 8) * z,
                z + rng.uniform(-200.0, 200.0, 8),
            )
        )
        normal = np.array([*rng.uniform(-1.5, 1.5, 2), -1.0])
        radii = rng.uniform(5.0, 40.0, 8)
        got = disc_centre_offsets(cam.K, centres, normal, radii)
        np.testing.assert_allclose(got, ref_offsets(cam.K, centres, normal, radii), atol=1e-10)


def test_blob_pixel_stats_equal_numpy():
    rng = np.random.default_rng(0)
    gray = rng.uniform(200, 900, (20, 30)).astype(np.float32)
    dist = rng.normal(3000, 4, (20, 30)).astype(np.float32)
    dist[5, 5] = np.nan
    flat = np.array([5 * 30 + 5, 5 * 30 + 6, 6 * 30 + 5, 6 * 30 + 6, 100], np.int64)
    starts = np.array([0, 4, 5], np.int64)
    cen = np.array([[5.5, 5.5], [10.0, 3.0]])
    shot, n_px, mad, unit, n_valid = blob_pixel_stats(flat, starts, cen, gray, dist, 100.0)
    rows, cols = np.divmod(flat[:4], 30)
    g = np.maximum(gray[rows, cols].astype(float), 1.0)
    amp = np.maximum(g - 100.0, 1.0)
    r2 = (cols - 5.5) ** 2 + (rows - 5.5) ** 2
    assert shot[0] == pytest.approx(np.sqrt((g * r2).sum()) / amp.sum(), rel=1e-12)
    d = dist[rows, cols]
    ok = np.isfinite(d)
    assert n_px.tolist() == [4, 1] and n_valid.tolist() == [3, 1]
    assert unit[0] == pytest.approx(np.mean(np.sqrt(g[ok]) / amp[ok]), rel=1e-12)
    assert mad[0] == pytest.approx(1.4826 * np.median(np.abs(d[ok] - np.median(d[ok]))))
    assert np.isnan(mad[1])  # fewer than 3 ranges: no own spread


@pytest.mark.parametrize("pooled", [True, False])
def test_blob_sigmas_equal_the_numpy_model(pooled):
    """The compiled sigmas against ``tofpose.stages.extraction.reference.sigmas``, on blobs of 1-40
    pixels,
    some split, some without ranges; with blobs large enough to pool the range model, and
    without (the uncalibrated sigma). The kernel's medians of float32 ranges are float32,
    the reference's float64: equal to 1e-6."""
    from tofpose.stages.extraction import uncertainty as u
    from tofpose.stages.extraction.kernels.sigmas import blob_sigmas
    from tofpose.stages.extraction.reference import sigmas as reference

    rng = np.random.default_rng(1)
    h, w = 60, 80
    gray = rng.uniform(60, 900, (h, w)).astype(np.float32)
    dist = rng.normal(4000, 6, (h, w)).astype(np.float32)
    dist[rng.random((h, w)) < 0.1] = np.nan
    sizes = [40, 12, 9, 3, 2, 1] if pooled else [5, 3, 2, 1]
    perm = rng.permutation(h * w)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    flat = perm[: starts[-1]].astype(np.int64)
    dist.reshape(-1)[flat[starts[-2] :]] = np.nan  # the last blob has no range
    cen = rng.uniform(5, 50, (len(sizes), 2))
    split = np.arange(len(sizes)) % 2 == 1
    constants = u.kernel_constants(u.SigmaFloors(0.03, 1.0))
    got = blob_sigmas(flat, starts, cen, gray, dist, 50.0, split, np.inf, constants)
    blobs = [flat[starts[j] : starts[j + 1]] for j in range(len(sizes))]
    want_px = [
        reference.centroid_sigma_px(gray, b, c, 50.0, bool(sp), constants)
        for b, c, sp in zip(blobs, cen, split, strict=True)
    ]
    np.testing.assert_allclose(got[0], want_px, rtol=1e-12)
    want_mm = reference.range_sigmas_mm(gray, dist, blobs, 50.0, constants)
    np.testing.assert_allclose(got[1], want_mm, rtol=1e-6)
    assert (got[1] == u.UNCALIBRATED_RANGE_SIGMA_MM).any() != pooled
    # a full scale below some blobs' brightest pixel: those get the clipped contour's term
    full_scale = 880.0
    clipped = np.array([(gray.reshape(-1)[b] >= full_scale).any() for b in blobs])
    assert clipped.any() and not clipped.all()
    sat = blob_sigmas(flat, starts, cen, gray, dist, 50.0, split, full_scale, constants)
    want_sat = [
        reference.centroid_sigma_px(gray, b, c, 50.0, bool(sp), constants, full_scale)
        for b, c, sp in zip(blobs, cen, split, strict=True)
    ]
    np.testing.assert_allclose(sat[0], want_sat, rtol=1e-12)
    # a blob all clipped is a binary image (q = 1): 1 / (12 pi r) per axis
    binary = blob_sigmas(flat, starts, cen, gray, dist, 50.0, split, 0.0, constants)
    n = np.diff(starts)
    term = np.sqrt(1.0 / (12.0 * np.pi * np.sqrt(n / np.pi)))
    np.testing.assert_allclose(binary[0] ** 2 - got[0] ** 2, term**2, rtol=1e-9)
    # a partly clipped blob gets at most that (nothing when its graded pixels outnumber
    # a disc's rim: these blobs are scattered pixels), an unclipped one nothing
    assert (sat[0][clipped] >= got[0][clipped]).all()
    assert (sat[0][clipped] <= binary[0][clipped]).all()
    np.testing.assert_array_equal(sat[0][~clipped], got[0][~clipped])


def test_point_residuals_are_the_distances_from_the_fitted_points():
    from scipy.spatial.transform import Rotation

    from tofpose.stages.pose.kernels.pose import point_residuals_mm
    from tofpose.stages.pose.reference.pose import (
        point_residuals_mm as reference_point_residuals_mm,
    )

    rng = np.random.default_rng(11)
    x = rng.normal(0.0, 200.0, (7, 3))
    R = Rotation.random(random_state=3).as_matrix()
    t = np.array([10.0, -20.0, 3000.0])
    y = x @ R.T + t + rng.normal(0.0, 2.0, (7, 3))
    res, rms = point_residuals_mm(x, y, R, t)
    want, want_rms = reference_point_residuals_mm(x, y, R, t)
    np.testing.assert_allclose(res, want, rtol=1e-12)
    assert rms == pytest.approx(want_rms, rel=1e-12)


def test_a_clipped_disc_gets_the_contour_term_of_its_clipped_share():
    """A disc of radius 5 px, 3x over full scale at its core (coverage-weighted rim):
    the rim pixels covered more than 1/3 are clipped. clipped_contour_sigma_px sees the
    rim's clipped share q near 1 - 1/3 and gives v(q) / (pi r), between the unclipped
    disc's 0 and a binary disc's 1 / (12 pi r)."""
    from tofpose.stages.extraction.kernels.sigmas import clipped_contour_sigma_px

    sub = 16
    yy, xx = np.mgrid[0 : 20 * sub, 0 : 20 * sub]
    inside = np.hypot((xx + 0.5) / sub - 10.2, (yy + 0.5) / sub - 9.7) <= 5.0
    coverage = inside.reshape(20, sub, 20, sub).mean(axis=(1, 3))
    gray = np.minimum(3.0 * coverage, 1.0)
    blob = coverage > 0.05
    n, n_clipped = int(blob.sum()), int((gray[blob] >= 1.0).sum())
    r = np.sqrt(n / np.pi)
    got = clipped_contour_sigma_px(n, n_clipped) ** 2 * np.pi * r
    q = 1.0 - 1.0 / 3.0
    assert got == pytest.approx(q**3 / 3 - q**4 / 4, rel=0.35)
    assert 0.0 < got < 1.0 / 12.0
    assert clipped_contour_sigma_px(n, 0) == 0.0
