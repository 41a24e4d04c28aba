"""PNG rendering and overlays."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from backend.services.live.imaging import (
    MATCHED_BGR,
    ImageRenderer,
    distance_to_bgr,
    downsample_png,
    gray_to_u8,
    render_png,
)
from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline


def _decode(png: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)


def test_gray_scale_is_monotonic_with_full_scale_white():
    g = np.array([[0, 100, 1000, 4095, 5000]], np.uint16)
    u8 = gray_to_u8(g)
    assert list(u8[0]) == sorted(u8[0]) and u8[0, 0] == 0 and u8[0, 3] == 255 == u8[0, 4]


def test_a_16_bit_cameras_full_scale_is_white_and_its_half_as_bright_as_the_12_bit_half():
    g = np.array([[0, 2048, 4095, 32768, 65535]], np.uint16)
    u8 = gray_to_u8(g, 65535.0)
    assert u8[0, 4] == 255 and u8[0, 2] < 70  # a 12-bit full scale is dim on 16 bits
    assert u8[0, 3] == gray_to_u8(np.array([[2048]], np.uint16))[0, 0]  # half is half
    with pytest.raises(ValueError, match="full_scale_counts must be positive"):
        gray_to_u8(g, 0.0)


def test_invalid_distances_are_black_and_valid_ones_are_coloured():
    d = np.full((4, 4), 2000.0, np.float32)
    d[0, 0] = np.nan
    d[3, 3] = 3000.0
    bgr = distance_to_bgr(d)
    assert bgr[0, 0].tolist() == [0, 0, 0]
    assert bgr[1, 1].sum() > 0 and bgr[3, 3].tolist() != bgr[1, 1].tolist()


def test_overlay_marks_each_matched_centroid_in_place():
    cam = CameraModel()
    f = render(facing_pose(1500.0), seed=0)
    res = PosePipeline(cam, paper_target()).process(f.gray, f.distance_mm)
    assert res.ok
    scale = 3
    img = _decode(render_png("gray", f.gray, f.distance_mm, res, overlay=True, scale=scale))
    plain = _decode(render_png("gray", f.gray, f.distance_mm, res, overlay=False, scale=scale))
    assert img.shape == (240 * scale, 320 * scale, 3)
    green = np.all(np.abs(img.astype(int) - MATCHED_BGR) < 60, axis=2) & ~np.all(
        np.abs(plain.astype(int) - MATCHED_BGR) < 60, axis=2
    )
    for m in res.matched:
        u, v = m.centroid_uv
        cx, cy = int((u + 0.5) * scale), int((v + 0.5) * scale)
        # The centroid cross passes within a pixel or two of the centroid.
        assert green[cy - 2 : cy + 3, cx - 2 : cx + 3].any(), m.catalog_id


def test_downsampled_png_has_the_reduced_size():
    f = render(facing_pose(2000.0), seed=0)
    assert _decode(downsample_png("gray", f.gray, f.distance_mm, 4)).shape[:2] == (60, 80)
    assert _decode(downsample_png("distance", f.gray, f.distance_mm, 1)).shape[:2] == (240, 320)


def _renderer_inputs():
    f = render(facing_pose(2000.0, 2, -3, 5))
    return f.gray, f.distance_mm


def test_renderer_renders_each_variant_once_per_frame_and_shares_it():
    gray, dist = _renderer_inputs()
    r = ImageRenderer(max_duty=1.0)
    try:
        a = r.png(7, "gray", gray, dist, None, overlay=False, scale=2)
        b = r.png(7, "gray", gray, dist, None, overlay=False, scale=2)
        assert a is b and a.result(5)[0] == 7
        assert _decode(a.result()[1]).shape[:2] == (480, 640)
        c = r.png(8, "gray", gray, dist, None, overlay=False, scale=2)  # a newer frame
        assert c is not a and c.result(5)[0] == 8
        r.png(8, "distance", gray, dist, None, overlay=False, scale=2).result(5)
        r.stream_png(8, "gray", gray, dist, 2).result(5)
        assert r.renders == 4
        assert r.cached_entries() == 3  # one per variant, never one per frame
    finally:
        r.close()


def test_renderer_rests_between_renders_to_cap_its_cpu_share():
    gray, dist = _renderer_inputs()
    r = ImageRenderer(max_duty=0.25)
    try:
        t0 = time.monotonic()
        for i in range(4):
            r.png(i, "distance", gray, dist, None, overlay=False, scale=4).result(10)
        elapsed = time.monotonic() - t0
    finally:
        r.close()
    # a rest of 3x the render time after each render: rendering is <= 1/4 of the time
    # from the first start to the end of the last render (3 rests in 4 renders)
    assert r.renders == 4
    assert r.busy_s / elapsed < 0.25 * 4 / 3 * 1.1, (r.busy_s, elapsed)


def test_renderer_refuses_a_bad_duty_cycle():
    with pytest.raises(ValueError, match="max_duty"):
        ImageRenderer(max_duty=0.0)
