"""PNG rendering and overlays."""

from __future__ import annotations

import cv2
import numpy as np

from backend.services.imaging import (
    MATCHED_BGR,
    distance_to_bgr,
    downsample_png,
    gray_to_u8,
    render_png,
)
from tests.conftest import facing_pose, render
from tofpose.camera import CameraModel
from tofpose.catalog import paper_target
from tofpose.pipeline import PosePipeline


def _decode(png: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)


def test_gray_scale_is_monotonic_with_full_scale_white():
    g = np.array([[0, 100, 1000, 4095, 5000]], np.uint16)
    u8 = gray_to_u8(g)
    assert list(u8[0]) == sorted(u8[0]) and u8[0, 0] == 0 and u8[0, 3] == 255 == u8[0, 4]


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
