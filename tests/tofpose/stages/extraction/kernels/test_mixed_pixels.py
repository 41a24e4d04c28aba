"""The mixing model of small markers (``tofpose.stages.extraction.kernels.mixed_pixels``) against
frames
built from the model's own physics with a known truth: a disc of known size and range,
area-integrated over the pixels, in front of a plate that is not black."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.stages.extraction.extraction import Blob, measure_blobs
from tofpose.stages.extraction.kernels.mixed_pixels import unmixed_range

DARK = 90.0  # counts with no return
PLATE_AMP, PLATE_MM = 120.0, 5120.0
MARKER_AMP, MARKER_MM = 1600.0, 5000.0


def _frame(centre_uv, radius_px, seed=0, noise=0.0):
    """(gray, distance, blob) of a disc over a plate: each pixel's coverage c from 16 x 16
    samples, amplitude and amplitude x distance mixed linearly (the phasor sum for a
    phase spread of 0.03 rad), gray = amplitude + DARK."""
    cam = CameraModel()
    h, w = cam.shape
    rng = np.random.default_rng(seed)
    cov = np.zeros((h, w))
    u0, v0 = centre_uv
    s = (np.arange(16) + 0.5) / 16 - 0.5
    for r in range(int(v0) - 4, int(v0) + 5):
        for c in range(int(u0) - 4, int(u0) + 5):
            uu, vv = np.meshgrid(c + s, r + s)
            cov[r, c] = np.mean((uu - u0) ** 2 + (vv - v0) ** 2 <= radius_px**2)
    amp = cov * MARKER_AMP + (1 - cov) * PLATE_AMP
    dist = (cov * MARKER_AMP * MARKER_MM + (1 - cov) * PLATE_AMP * PLATE_MM) / amp
    gray = (amp + DARK + noise * rng.standard_normal((h, w))).astype(np.float32)
    dist = (dist + noise * 0.05 * rng.standard_normal((h, w))).astype(np.float32)
    member = gray > DARK + PLATE_AMP + 0.15 * (MARKER_AMP - PLATE_AMP) * cov.max()
    pixels = np.flatnonzero(member)
    rows, cols = np.divmod(pixels, w)
    bbox = (int(cols.min()), int(rows.min()), int(np.ptp(cols)) + 1, int(np.ptp(rows)) + 1)
    return cam, gray, dist, Blob(pixels=pixels, area_px=len(pixels), bbox=bbox)


@pytest.mark.parametrize("centre", [(150.3, 120.6), (151.0, 119.5), (149.72, 121.18)])
@pytest.mark.parametrize("radius_px", [0.7, 1.2, 2.0])
def test_a_small_marker_over_a_grey_plate_has_its_own_range_and_centre(centre, radius_px):
    cam, gray, dist, blob = _frame(centre, radius_px)
    (m,) = measure_blobs([blob], gray, dist, cam, float(np.median(gray)), dark=DARK)
    # the median of its pixels is pulled towards the plate behind it ...
    assert m.distance_mm - MARKER_MM > 0.5
    # ... the model, given the disc's area, is not
    rho, sens = unmixed_range(m.distance_mm, m.mixing, radius_px, 1.0, 4.0)
    assert rho == pytest.approx(MARKER_MM, abs=0.2)  # 16 x 16 samples vs pi r^2
    assert sens > 0  # and it says how much a wrong area would move it
    # the centroid above the blob's own surround level is the disc's centre
    np.testing.assert_allclose(m.centroid_uv, centre, atol=0.05)  # 0.04 px at r = 0.7 px


def test_the_model_does_not_apply_where_it_cannot():
    cam, gray, dist, blob = _frame((150.3, 120.6), 1.0)
    (m,) = measure_blobs([blob], gray, dist, cam, float(np.median(gray)), dark=DARK)
    assert unmixed_range(m.distance_mm, m.mixing, 5.0, 1.0, 4.0) == (m.distance_mm, 0.0)
    nan_row = np.full_like(m.mixing, np.nan)
    assert unmixed_range(m.distance_mm, nan_row, 1.0, 1.0, 4.0) == (m.distance_mm, 0.0)
    (no_dark,) = measure_blobs([blob], gray, dist, cam, float(np.median(gray)))
    assert unmixed_range(no_dark.distance_mm, no_dark.mixing, 1.0, 1.0, 4.0)[0] == (
        no_dark.distance_mm
    )  # without the frame's no-return level the amplitudes are unknown


def test_with_noise_the_model_stays_closer_than_the_median():
    errs_model, errs_median = [], []
    for seed in range(20):
        cam, gray, dist, blob = _frame((150.3 + 0.05 * seed, 120.6), 0.8, seed, noise=10.0)
        (m,) = measure_blobs([blob], gray, dist, cam, float(np.median(gray)), dark=DARK)
        errs_model.append(unmixed_range(m.distance_mm, m.mixing, 0.8, 1.0, 4.0)[0] - MARKER_MM)
        errs_median.append(m.distance_mm - MARKER_MM)
    assert abs(np.median(errs_model)) < 0.5 * abs(np.median(errs_median))


# -- a marker partly hidden by something in front of it ----------------------------------
def _occluded(blob, dist):
    from tofpose.stages.extraction.kernels.centroids import owner_map
    from tofpose.stages.extraction.kernels.mixed_pixels import occluded_blobs

    flat = np.asarray(blob.pixels, np.int64)
    starts = np.array([0, len(flat)], np.int64)
    bbox = np.array([blob.bbox], np.int64)
    owners = owner_map(flat, starts, bbox, *dist.shape)
    rho = np.array([float(np.median(dist.reshape(-1)[flat]))])
    return bool(occluded_blobs(flat, starts, bbox, dist.astype(np.float32), rho, owners)[0])


def test_a_marker_with_an_arm_across_its_edge_is_occluded_and_noise_is_not():
    """An arm 500 mm in front of a 3 px marker, covering the rows above it (the plate
    around: ranged, or too dark to range): occluded. The same marker on a plate whose
    ranges scatter by 400 mm (dark, strong ambient: many pixels read 250 mm near by
    chance, some of them touching), with one near pixel, or with its whole rim reading
    near (a marker moving during the exposure): not."""
    cam, gray, dist, blob = _frame((150.3, 120.6), 1.5)
    assert not _occluded(blob, dist)
    top = blob.bbox[1]
    arm = dist.copy()
    arm[top - 3 : top, 140:161] = MARKER_MM - 500.0
    assert _occluded(blob, arm)
    dark_plate = arm.copy()
    ring = np.zeros_like(dist, bool)
    ring[top - 3 : top + blob.bbox[3] + 3, 140:161] = True
    member = np.zeros(dist.size, bool)
    member[blob.pixels] = True
    member = member.reshape(dist.shape)
    dark_plate[ring & ~member & (np.abs(arm - PLATE_MM) < 1.0)] = np.nan
    assert _occluded(blob, dark_plate)  # the arm alone is ranged around it
    rng = np.random.default_rng(4)
    hits = 0
    for _ in range(50):
        noisy = dist.copy()
        plate = ring & ~member & (np.abs(dist - PLATE_MM) < 1.0)
        noisy[plate] += rng.normal(0.0, 400.0, plate.sum())
        hits += _occluded(blob, noisy)
    assert hits == 0
    one = dist.copy()
    one[top - 1, int(150.3)] = MARKER_MM - 800.0
    assert not _occluded(blob, one)
    # nothing ranged around the marker but the arm (the noise estimate has no pixels)
    only_arm = arm.copy()
    only_arm[ring & ~member & (np.abs(arm - (MARKER_MM - 500.0)) > 1.0)] = np.nan
    assert _occluded(blob, only_arm)
    # isolated near pixels on a quiet plate (30 mm scatter: the noise rule alone would
    # let them through): no connected patch, not occluded
    speckle = dist.copy()
    quiet = ring & ~member & (np.abs(dist - PLATE_MM) < 1.0)
    speckle[quiet] += rng.normal(0.0, 30.0, quiet.sum())
    rows, cols = np.nonzero(quiet)
    lone = (rows % 2 == 0) & (cols % 2 == 0)  # every other pixel: none 8-connected
    speckle[rows[lone], cols[lone]] = MARKER_MM - 800.0
    assert not _occluded(blob, speckle)
    # a moving marker: its whole rim reads wrong (sub-frames see the edge at different
    # places), nothing beyond it does
    rim = cv2.dilate(member.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    smeared = dist.copy()
    smeared[rim & ~member] = MARKER_MM - 900.0
    assert not _occluded(blob, smeared)


def test_a_saturated_marker_at_the_plates_edge_reads_its_own_range_not_the_walls():
    """The physics study's ``saturating`` family at 3 m (a fixed exposure, the
    reflectors at 2-5x full scale), frame 3 of its draws with seed (5, 30): marker 8
    sits at the plate's edge, so the ring around its blob is mostly the wall
    behind the target, and the wall pixels beside the blob read the ring's own distance. Each such
    pixel bounded the reflector at the wall's distance with a narrow interval, and
    while every support pixel bounded it (before 2026-12-08) they won the weighted
    median: the marker read 2.8 m long (sigma 0.7 m). Only the blob's own ranged pixels
    bound a saturated reflector now: every saturated marker reads its range within
    30 mm and within 3 of its sigmas."""
    from tofpose.core.catalog import paper_target
    from tofpose.pipeline import PosePipeline
    from tofpose.sim.randomise import draw_frame

    cat = paper_target()
    rng = np.random.default_rng([5, 30])
    for _ in range(3):
        drawn = draw_frame("saturating", 3.0, rng, cat)
        frame = drawn.render(rng)
    r = PosePipeline(drawn.camera, cat).process(frame.gray, frame.distance_mm)
    assert r.ok, r.reason
    T = drawn.T_camera_target
    centres = cat.positions_mm @ T.R.T + T.t_mm
    saturated = [m for m in r.matched if m.saturated]
    assert 8 in [m.catalog_id for m in saturated]
    for m in saturated:
        true_mm = float(np.linalg.norm(centres[list(cat.ids).index(m.catalog_id)]))
        error = m.distance_mm - true_mm
        assert abs(error) < 30.0 and abs(error) < 3.0 * m.range_sigma_mm, (m.catalog_id, error)
