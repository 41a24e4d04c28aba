"""Measurement sigmas against the simulator's truth (tofpose.stages.extraction.uncertainty)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bench.accuracy import random_pose
from tofpose import CameraModel, PosePipeline, paper_target
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.stages.extraction.extraction import Blob
from tofpose.stages.extraction.uncertainty import SigmaFloors, measurement_sigmas, sampling_sigma_px


def test_sampling_sigma_is_one_pixel_uniform_for_one_pixel_and_falls_with_size():
    s = sampling_sigma_px(np.array([1, 2, 4, 9, 100]))
    assert s[0] == pytest.approx(1 / np.sqrt(12))
    assert np.all(np.diff(s) < 0) and s[-1] < 1e-3


def _square_blob(u0: int, v0: int, side: int, width: int) -> Blob:
    rows, cols = np.mgrid[v0 : v0 + side, u0 : u0 + side]
    return Blob(
        pixels=(rows * width + cols).ravel(),
        area_px=side * side,
        bbox=(u0, v0, side, side),
        centroid_uv=np.array([u0 + (side - 1) / 2, v0 + (side - 1) / 2]),
    )


def test_few_pixel_blob_takes_the_range_noise_the_frame_pools_from_larger_blobs():
    """Three pixels that happen to agree exactly (MAD 0) must not claim a perfect range:
    the pooled CW-ToF model of the frame's large blobs (same brightness) sets their sigma."""
    rng = np.random.default_rng(0)
    gray = np.full((60, 80), 50.0)
    dist = np.full((60, 80), np.nan)
    big = _square_blob(10, 10, 8, 80)
    small = _square_blob(50, 30, 2, 80)
    small = replace(small, pixels=small.pixels[:3], area_px=3)
    for b in (big, small):
        r, c = np.divmod(b.pixels, 80)
        gray[r, c] = 850.0
    r, c = np.divmod(big.pixels, 80)
    dist[r, c] = 5000.0 + 6.0 * rng.standard_normal(len(r))
    r, c = np.divmod(small.pixels, 80)
    dist[r, c] = 5000.0
    sp, sr = measurement_sigmas([big, small], gray, dist, 50.0, SigmaFloors(0.03, 0.1))
    per_pixel_big = sr[0] * np.sqrt(64) / 1.2533
    assert per_pixel_big == pytest.approx(6.0, rel=0.35)
    assert sr[1] == pytest.approx(1.2533 * per_pixel_big / np.sqrt(3), rel=0.05)
    assert sp[1] > sp[0]  # 3 pixels locate a centre worse than 64


@pytest.mark.parametrize(
    ("range_m", "centroid_rms", "range_rms"),
    [(5.7, (0.55, 1.1), (0.8, 1.3)), (12.0, (0.4, 1.1), (0.8, 1.6))],
)
def test_predicted_sigmas_match_the_actual_errors(range_m, centroid_rms, range_rms):
    """Normalised errors (actual / predicted) of matched reflectors, RMS over ~100 of
    them (its own Monte-Carlo spread ~7 %). Centroid sigmas cover the errors and are
    wider than the simulator's (0.71 at 5.7 m, 0.50 at 12 m in this run: the 0.03 px
    floor stands for what the simulator lacks, docs/algorithm.md); the old model
    (floor only, no sampling term) gave 2.0 at 12 m. Range sigmas are right at 5.7 m
    (1.11) and ~45 % narrow at 12 m (1.45), beyond the paper target's 8 m design range:
    a known limit the bounds record, not a margin."""
    cam, cat = CameraModel(), paper_target()
    scene, pipe = TargetScene(cat), PosePipeline(cam, cat)
    xyz = dict(zip(cat.ids.tolist(), cat.positions_mm, strict=True))
    rng = np.random.default_rng(11)
    z_px, z_rng = [], []
    for _ in range(12):
        T = random_pose(range_m, rng)
        f = render_frame(cam, scene, T, SensorModel(), rng)
        pipe.reset()
        res = pipe.process(f.gray, f.distance_mm)
        if not res.ok or res.covariance is None:
            continue
        for m in res.matched:
            true = T.apply(xyz[m.catalog_id][None])[0]
            z_px.extend((m.centroid_uv - cam.project(true[None])[0]) / m.centroid_sigma_px)
            z_rng.append((m.distance_mm - np.linalg.norm(true)) / m.range_sigma_mm)
    assert len(z_rng) >= 40
    assert centroid_rms[0] < np.sqrt(np.mean(np.square(z_px))) < centroid_rms[1]
    assert range_rms[0] < np.sqrt(np.mean(np.square(z_rng))) < range_rms[1]


def _merged_pair_z_px(draw, rng, n_frames):
    """Normalised centroid errors (per image axis) of markers 7 and 8 over ``n_frames``
    simulated frames at the poses ``draw()`` gives, in the frames where they merged into
    one component (an "oversize" rejection): a list of floats."""
    cam, cat = CameraModel(), paper_target()
    scene, pipe = TargetScene(cat), PosePipeline(cam, cat)
    xyz = dict(zip(cat.ids.tolist(), cat.positions_mm, strict=True))
    z_px: list[float] = []
    for _ in range(n_frames):
        T = draw()
        f = render_frame(cam, scene, T, SensorModel(), rng)
        pipe.reset()
        res = pipe.process(f.gray, f.distance_mm)
        if not res.ok or not any(b.reason == "oversize" for b in res.rejected):
            continue  # no merged component in this frame
        for m in res.matched:
            if m.catalog_id in (7, 8):
                true = T.apply(xyz[m.catalog_id][None])[0]
                z_px.extend((m.centroid_uv - cam.project(true[None])[0]) / m.centroid_sigma_px)
    return z_px


def test_split_halves_of_merged_markers_get_sigmas_that_cover_their_errors():
    """At 8 m markers 7 and 8 image as one component, split into two halves (§3.3, ours)
    whose centroids keep some of the neighbour's light. Their normalised centroid errors
    must have an RMS near 1 (the spread of an RMS of 64 values is ~9 %): with shot noise,
    floor and sampling only it was ~3 on these frames, and the fit leaned on two biased
    bearings."""
    from bench.realistic import long_range_pose

    rng = np.random.default_rng(5)
    z_px = _merged_pair_z_px(lambda: long_range_pose(8.0, rng), rng, 16)
    assert len(z_px) >= 20
    assert 0.8 < np.sqrt(np.mean(np.square(z_px))) < 1.4  # 1.31 in this run, 64 values


def test_parts_of_merged_markers_near_range_get_sigmas_that_cover_their_errors():
    """At 3 m with the target tilted up to 20 deg, markers 7 and 8 often touch in the
    image; the ellipse stage cuts the component into parts of 70-80 px. A cut assigns
    part of the contact band's light to the wrong side, a fraction of a pixel whatever
    the parts' size: with the old term (0.25 px / sqrt(n), 0.03 px here) their
    normalised centroid errors had an RMS near 3 and the fit dropped good markers to
    keep them. With the cut's own sigma the RMS is near 1."""
    from bench.physics import MAX_ATTITUDE_DEG, OFFSET_FRACTION
    from tofpose.sim.randomise import draw_pose

    rng = np.random.default_rng(11)
    cam = CameraModel()
    z_px = _merged_pair_z_px(
        lambda: draw_pose(3.0, rng, cam, MAX_ATTITUDE_DEG, OFFSET_FRACTION), rng, 40
    )
    assert len(z_px) >= 20
    assert 0.6 < np.sqrt(np.mean(np.square(z_px))) < 1.5  # 0.62 here, 60 values (1.72 before)
