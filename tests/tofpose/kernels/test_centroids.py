"""Blob centroids and ranges against a plain NumPy/OpenCV statement of the same method
(``tofpose.extraction.measure_blobs``'s docstring)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.camera import CameraModel
from tofpose.catalog import paper_target
from tofpose.extraction import (
    ExtractionConfig,
    check_frame,
    find_candidate_blobs,
    frame_levels,
    measure_blobs,
)


def _surround_level(blob, gray, owner, j, frame_bg):
    """The median gray of the ring between the blob's box grown by 1 and by 3 px (other
    blobs' pixels left out), or the frame's level without one."""
    h, w = gray.shape
    x, y, bw, bh = blob.bbox
    ring = np.zeros((h, w), bool)
    ring[max(y - 3, 0) : y + bh + 3, max(x - 3, 0) : x + bw + 3] = True
    ring[max(y - 1, 0) : y + bh + 1, max(x - 1, 0) : x + bw + 1] = False
    if owner is not None:
        ring &= (owner == -1) | (owner == j)
    return float(np.median(gray[ring])) if ring.any() else frame_bg


def _reference(blob, gray, dist, cam, frame_bg, owner=None, j=0):
    """Coverage-weighted centroid over the blob dilated by one pixel, above the blob's
    surround level, then the median of the member ranges projected on the centroid's
    line of sight."""
    bg = _surround_level(blob, gray, owner, j, frame_bg)
    h, w = gray.shape
    x, y, bw, bh = blob.bbox
    y0, y1, x0, x1 = max(y - 2, 0), min(y + bh + 2, h), max(x - 2, 0), min(x + bw + 2, w)
    rows, cols = np.divmod(blob.pixels, w)
    m = np.zeros((y1 - y0, x1 - x0), np.uint8)
    m[rows - y0, cols - x0] = 1
    ring = cv2.dilate(m, np.ones((3, 3), np.uint8)).astype(bool)
    if owner is not None:
        o = owner[y0:y1, x0:x1]
        ring &= (o == -1) | (o == j)
    patch = np.maximum(gray[y0:y1, x0:x1] - bg, 0.0).astype(np.float32)
    local = cv2.dilate(np.where(m > 0, patch, 0).astype(np.float32), np.ones((3, 3), np.uint8))
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = np.clip(patch / local, 0, 1)
    cov[~np.isfinite(cov)] = 0
    rr, cc = np.nonzero(ring)
    wts = cov[ring].astype(float)
    uv = np.array([(wts * (cc + x0)).sum() / wts.sum(), (wts * (rr + y0)).sum() / wts.sum()])
    e_c = cam.bearings(uv[None])[0]
    d = dist[rows, cols]
    ok = np.isfinite(d)
    along = d[ok] * (cam.pixel_bearings()[rows[ok], cols[ok]] @ e_c)
    return uv, float(np.median(along))


@pytest.mark.parametrize("distance_mm", [700.0, 2000.0, 6000.0])
def test_measured_blobs_equal_the_reference(distance_mm):
    cam, cat, cfg = CameraModel(), paper_target(), ExtractionConfig()
    frame = render(facing_pose(distance_mm, 5, -3, 20, offset_mm=(30.0, 20.0)), seed=2)
    g, d = check_frame(cam, frame.gray, frame.distance_mm)
    found = find_candidate_blobs(g, d, cam, cat.diameters_mm, cfg, frame_levels(g, cfg))
    bg = found.stats.background
    measured = measure_blobs(found.accepted, g, d, cam, bg)
    assert len(measured) == len(found.accepted) >= 3
    owner = np.full(cam.shape, -1, np.int32)
    for j, b in enumerate(found.accepted):
        owner.ravel()[b.pixels] = j
    for j, (b, m) in enumerate(zip(found.accepted, measured, strict=True)):
        uv, rho = _reference(b, g, d, cam, bg, owner, j)
        np.testing.assert_allclose(m.centroid_uv, uv, atol=1e-9)
        assert m.distance_mm == pytest.approx(rho, abs=1e-6)
        assert b.distance_mm != m.distance_mm or b.centroid_uv is not m.centroid_uv  # new


def test_touching_blobs_do_not_pull_each_other():
    """Two blobs side by side: each one's ring excludes the other's pixels (owner map)."""
    cam = CameraModel()
    g = np.full(cam.shape, 5.0, np.float32)
    d = np.full(cam.shape, 3000.0, np.float32)
    g[100:106, 100:106] = 900.0
    g[100:106, 106:112] = 300.0
    w = cam.width
    from tofpose.extraction import Blob

    def blob(c0):
        r, c = np.mgrid[100:106, c0 : c0 + 6]
        return Blob(pixels=(r * w + c).ravel(), area_px=36, bbox=(c0, 100, 6, 6))

    a, b = blob(100), blob(106)
    owner = np.full(cam.shape, -1, np.int32)
    owner.ravel()[a.pixels], owner.ravel()[b.pixels] = 0, 1
    ma, mb = measure_blobs([a, b], g, d, cam, 5.0)
    for j, (orig, m) in enumerate(((a, ma), (b, mb))):
        uv, _ = _reference(orig, g, d, cam, 5.0, owner, j)
        np.testing.assert_allclose(m.centroid_uv, uv, atol=1e-9)
    assert ma.centroid_uv[0] == pytest.approx(102.5, abs=0.05)  # not pulled to the right


@pytest.mark.parametrize("corner", ["top-left", "bottom-right"])
def test_blobs_at_the_image_border_and_with_dark_members_equal_the_reference(corner):
    """Random ragged blobs cut by the image border (their dilated box is clipped), some
    members below the background (weight 0): the compiled centroid equals the reference."""
    from tofpose.extraction import Blob

    cam = CameraModel()
    h, w = cam.shape
    rng = np.random.default_rng(5)
    d = np.full(cam.shape, 2500.0, np.float32)
    for _ in range(20):
        g = rng.normal(60.0, 40.0, cam.shape).astype(np.float32)
        member = np.zeros(cam.shape, bool)
        r0, c0 = (0, 0) if corner == "top-left" else (h - 9, w - 11)
        member[r0 : r0 + 9, c0 : c0 + 11] = rng.random((9, 11)) < 0.6
        pixels = np.flatnonzero(member)
        rows, cols = np.divmod(pixels, w)
        bbox = (int(cols.min()), int(rows.min()), int(np.ptp(cols)) + 1, int(np.ptp(rows)) + 1)
        blob = Blob(pixels=pixels, area_px=len(pixels), bbox=bbox)
        (m,) = measure_blobs([blob], g, d, cam, 50.0)
        uv, _ = _reference(blob, g, d, cam, 50.0)
        np.testing.assert_allclose(m.centroid_uv, uv, atol=1e-9)


def test_a_blob_across_the_whole_image_width_equals_the_reference():
    """A band of full rows: each row's last pixel and the next row's first are
    consecutive flat indices, but the member values are filled run by run and a run
    must end with its row."""
    from tofpose.extraction import Blob

    cam = CameraModel()
    h, w = cam.shape
    rng = np.random.default_rng(6)
    g = rng.normal(60.0, 40.0, cam.shape).astype(np.float32)
    g[100:104] += np.linspace(300.0, 900.0, w, dtype=np.float32)  # brighter to the right
    d = np.full(cam.shape, 2500.0, np.float32)
    pixels = np.arange(100 * w, 104 * w, dtype=np.int64)
    blob = Blob(pixels=pixels, area_px=len(pixels), bbox=(0, 100, w, 4))
    (m,) = measure_blobs([blob], g, d, cam, 50.0)
    uv, _ = _reference(blob, g, d, cam, 50.0)
    np.testing.assert_allclose(m.centroid_uv, uv, atol=1e-9)
