"""The reference statement of §3.3's helpers (``tofpose.stages.ellipses.reference.ellipses``)
against the
compiled ones (``tofpose.stages.ellipses.kernels.ellipses``) on random and rendered blobs, and
against
known truth on drawn discs and ellipses.

Equality: ``blob_mask`` and ``arc_points`` exact (the same mask; the same indices and
arc starts); ``ellipse_rms_px`` to 1e-12 relative (the kernel's radius along the ray
without angles against r_e(theta) with theta = atan2)."""

from __future__ import annotations

from functools import cache

import cv2
import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.stages.ellipses.ellipse import blob_contour, fit_ellipse
from tofpose.stages.ellipses.kernels import ellipses as kernel
from tofpose.stages.ellipses.reference import ellipses as reference


@cache
def _rendered_blobs(distance_mm, distorted):
    """The 8-connected components (flat pixels, bbox (x, y, w, h)) of the paper target's
    frame at ``distance_mm`` above a quarter of its peak, width of the frame."""
    cam = CameraModel(dist=(-0.02, 0.008, 0.0004, -0.0003, 0.0)) if distorted else CameraModel()
    gray = render(facing_pose(distance_mm, 5, -8, 15), seed=3, camera=cam).gray
    n, labels, stats, _ = cv2.connectedComponentsWithStats(
        (gray >= 0.25 * gray.max()).astype(np.uint8), connectivity=8
    )
    blobs = [
        (np.flatnonzero(labels == k), tuple(int(v) for v in stats[k, :4])) for k in range(1, n)
    ]
    return blobs, gray.shape[1]


def _random_contours(rng, count):
    """Outer contours of one to three overlapping filled ellipses (merged markers), some
    with speckle ((P, 2) float32, as ``blob_contour`` gives them)."""
    out = []
    for _ in range(count):
        mask = np.zeros((40, 60), np.uint8)
        for _ in range(rng.integers(1, 4)):
            centre = (float(rng.uniform(10, 50)), float(rng.uniform(10, 30)))
            axes = (float(rng.uniform(4, 25)), float(rng.uniform(4, 20)))
            cv2.ellipse(mask, (centre, axes, float(rng.uniform(0, 180))), 1, -1)
        if rng.random() < 0.3:
            mask[rng.random(mask.shape) < 0.05] = 1
        out.append(blob_contour(mask))
    return out


RENDERED = [(z, d) for z in (700.0, 2000.0, 5000.0, 8000.0) for d in (False, True)]


@pytest.mark.parametrize(("distance_mm", "distorted"), RENDERED)
def test_blob_mask_equals_the_kernel_on_rendered_blobs(distance_mm, distorted):
    blobs, width = _rendered_blobs(distance_mm, distorted)
    assert len(blobs) >= 4
    for pixels, (x, y, bw, bh) in blobs:
        want = kernel.blob_mask(pixels, x, y, bw, bh, width)
        got = reference.blob_mask(pixels, x, y, bw, bh, width)
        assert got.dtype == want.dtype == np.uint8
        np.testing.assert_array_equal(got, want)


def test_blob_mask_equals_the_kernel_on_random_pixel_sets():
    rng = np.random.default_rng(1)
    for _ in range(300):
        width = int(rng.integers(20, 80))
        x, y = (int(v) for v in rng.integers(0, 15, 2))
        bw, bh = (int(v) for v in rng.integers(1, 6, 2))
        rows, cols = np.mgrid[y : y + bh, x : x + bw]
        keep = rng.random(rows.size) < 0.6
        pixels = (rows.ravel() * width + cols.ravel())[keep].astype(np.int64)
        np.testing.assert_array_equal(
            reference.blob_mask(pixels, x, y, bw, bh, width),
            kernel.blob_mask(pixels, x, y, bw, bh, width),
        )


def test_the_mask_of_a_drawn_disc_is_the_disc():
    """A disc drawn in a 50 x 70 image: its mask in the padded box is the drawn patch, with
    a zero border."""
    img = np.zeros((50, 70), np.uint8)
    cv2.circle(img, (31, 22), 9, 1, -1)
    pixels = np.flatnonzero(img)
    rows, cols = np.divmod(pixels, 70)
    x, y, bw, bh = cols.min(), rows.min(), np.ptp(cols) + 1, np.ptp(rows) + 1
    assert (bw, bh) == (19, 19)
    mask = reference.blob_mask(pixels, x, y, bw, bh, 70)
    np.testing.assert_array_equal(mask, img[y - 1 : y + bh + 1, x - 1 : x + bw + 1])
    assert mask[0].sum() == mask[-1].sum() == mask[:, 0].sum() == mask[:, -1].sum() == 0


def _arcs_agree(contour, **kw):
    want_index, want_starts = kernel.arc_points(
        contour, kw["angle_deg"], kw["min_points"], kw["smooth_sigma"]
    )
    got_index, got_starts = reference.arc_points(contour, **kw)
    np.testing.assert_array_equal(got_starts, want_starts)
    np.testing.assert_array_equal(got_index, want_index)
    return len(got_starts) - 1


def test_arc_points_equals_the_kernel_on_random_contours():
    rng = np.random.default_rng(0)
    n_arcs = n_checked = 0
    for contour in _random_contours(rng, 300):
        contour = contour.astype(np.float64)
        for min_points, angle_deg, sigma in ((4, 40.0, 2.0), (6, 40.0, 2.0), (9, 30.0, 1.5)):
            if len(contour) < 2 * min_points:
                continue
            n_arcs += _arcs_agree(
                contour, angle_deg=angle_deg, min_points=min_points, smooth_sigma=sigma
            )
            n_checked += 1
    assert n_checked > 600 and n_arcs > n_checked  # the contours do break into arcs


@pytest.mark.parametrize(("distance_mm", "distorted"), RENDERED)
def test_arc_points_and_the_residual_equal_the_kernel_on_rendered_blobs(distance_mm, distorted):
    blobs, width = _rendered_blobs(distance_mm, distorted)
    checked = 0
    for pixels, (x, y, bw, bh) in blobs:
        pts = blob_contour(reference.blob_mask(pixels, x, y, bw, bh, width), (x - 1, y - 1))
        if len(pts) < 8:
            continue
        min_points = 6 if len(pts) >= 12 else 4
        _arcs_agree(pts.astype(np.float64), angle_deg=40.0, min_points=min_points, smooth_sigma=2.0)
        e = fit_ellipse(pts)
        assert e is not None
        (cx, cy), (a1, a2), ang = e
        want = kernel.ellipse_rms_px(cx, cy, a1, a2, ang, pts.astype(np.float64))
        assert reference.ellipse_rms_px(cx, cy, a1, a2, ang, pts) == pytest.approx(want, rel=1e-12)
        checked += 1
    assert checked >= 2


def test_ellipse_rms_equals_the_kernel_near_random_ellipses():
    """Points scattered about random ellipses' outlines (as a contour lies), and one at
    the centre (theta = atan2(0, 0) = 0)."""
    rng = np.random.default_rng(4)
    for _ in range(300):
        centre, axes = rng.uniform(0, 300, 2), rng.uniform(2, 60, 2)
        ang = rng.uniform(-90, 270)
        s = rng.uniform(0, 2 * np.pi, 30)
        turn = np.radians(ang)
        local = np.column_stack((np.cos(s), np.sin(s))) * axes / 2 + rng.normal(0, 0.7, (30, 2))
        pts = centre + local @ np.array(
            [[np.cos(turn), np.sin(turn)], [-np.sin(turn), np.cos(turn)]]
        )
        pts = np.vstack((centre, pts))
        args = (*centre, *axes, ang, pts)
        assert reference.ellipse_rms_px(*args) == pytest.approx(
            kernel.ellipse_rms_px(*args), rel=1e-12
        )


def test_the_residual_of_known_points():
    """Points on an ellipse have residual 0; points on a circle 1.5 px outside a circular
    'ellipse' have residual 1.5 (exact for circles); the drawn disc's contour (its outer
    pixels' centres) is within 0.4 px RMS of a circle half a pixel inside its edge."""
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    x, y = 12.0 * np.cos(t), 5.0 * np.sin(t)  # semi-axes 12 and 5, turned by 30 deg
    pts = np.column_stack((40 + c * x - s * y, 30 + s * x + c * y))
    assert reference.ellipse_rms_px(40.0, 30.0, 24.0, 10.0, 30.0, pts) < 1e-12
    ring = np.column_stack((40 + 8.5 * np.cos(t), 30 + 8.5 * np.sin(t)))
    assert reference.ellipse_rms_px(40.0, 30.0, 14.0, 14.0, 70.0, ring) == pytest.approx(1.5)
    img = np.zeros((60, 80), np.uint8)
    cv2.circle(img, (40, 30), 10, 1, -1)
    assert reference.ellipse_rms_px(40.0, 30.0, 19.0, 19.0, 0.0, blob_contour(img)) < 0.4


def test_two_overlapping_discs_break_into_two_arcs_at_their_own_centres():
    """The outline of two overlapping drawn discs breaks at the two concave points into
    two arcs (AC/CC), each fitting an ellipse at its disc's centre within 1 px; one disc's
    outline does not break at all."""
    img = np.zeros((60, 90), np.uint8)
    cv2.circle(img, (30, 30), 12, 1, -1)
    cv2.circle(img, (50, 30), 12, 1, -1)
    contour = blob_contour(img).astype(np.float64)
    index, starts = reference.arc_points(contour, 40.0, 6, 2.0)
    assert len(starts) == 3
    centres = sorted(fit_ellipse(contour[index[starts[a] : starts[a + 1]]])[0] for a in range(2))
    np.testing.assert_allclose(centres, [[30, 30], [50, 30]], atol=1.0)
    one = np.zeros((60, 90), np.uint8)
    cv2.circle(one, (40, 30), 12, 1, -1)
    contour = blob_contour(one).astype(np.float64)
    index, starts = reference.arc_points(contour, 40.0, 6, 2.0)
    np.testing.assert_array_equal(index, np.arange(len(contour)))
    np.testing.assert_array_equal(starts, [0, len(contour)])
