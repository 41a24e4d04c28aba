"""ROS 2 Image and CameraInfo messages -> our arrays and camera."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tofpose.core.camera import CameraModel
from tofpose.io.interop.ros2_images import (
    Ros2MessageError,
    amplitude_counts,
    camera_from_info,
    depth_mm,
    image_pixels,
)


def msg(a: np.ndarray, encoding: str, *, big_endian=False, pad=0):
    """An Image-like message of ``a`` with ``pad`` bytes after each row."""
    a = np.ascontiguousarray(a, a.dtype.newbyteorder(">" if big_endian else "<"))
    h, w = a.shape
    rows = np.frombuffer(a.tobytes(), np.uint8).reshape(h, -1)
    data = np.hstack((rows, np.zeros((h, pad), np.uint8))).ravel()
    return SimpleNamespace(
        height=h, width=w, step=w * a.itemsize + pad, encoding=encoding,
        is_bigendian=int(big_endian), data=data,
    )  # fmt: skip


def test_padded_big_endian_rows():
    a = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000
    np.testing.assert_array_equal(image_pixels(msg(a, "mono16", big_endian=True, pad=6), "u2"), a)
    np.testing.assert_array_equal(amplitude_counts(msg(a.astype(np.uint8), "mono8")), a % 256)


def test_depth_units_and_invalid():
    z_m = np.array([[1.5, np.nan, 0.0, np.inf]], np.float32)
    assert_allclose(depth_mm(msg(z_m, "32FC1")), [[1500.0, np.nan, np.nan, np.nan]])
    z_mm = np.array([[1500, 0]], np.uint16)
    assert_allclose(depth_mm(msg(z_mm, "16UC1")), [[1500.0, np.nan]])


def test_short_data_is_named():
    m = msg(np.zeros((3, 4), np.uint16), "mono16")
    m.data = m.data[:-1]
    with pytest.raises(Ros2MessageError, match="mono16 image of 4 x 3 has 23 bytes"):
        amplitude_counts(m)


def info(model: str, d: list[float]):
    k = [400.0, 0, 160.0, 0, 410.0, 120.0, 0, 0, 1]
    return SimpleNamespace(
        width=320, height=240, k=np.array(k), d=np.array(d), distortion_model=model
    )


@pytest.mark.parametrize(
    ("model", "d", "dist"),
    [
        ("plumb_bob", [-0.2, 0.05, 1e-3, 2e-3, 0.01], (-0.2, 0.05, 1e-3, 2e-3, 0.01)),
        ("", [], (0.0, 0.0, 0.0, 0.0, 0.0)),
        ("rational_polynomial", [0.1, 0, 0, 0, 0, 0, 0, 0], (0.1, 0.0, 0.0, 0.0, 0.0)),
        # k4 = k1: (1 + k1 r^2) / (1 + k1 r^2), an ideal lens
        ("rational_polynomial", [0.3, 0, 0, 0, 0, 0.3, 0, 0], (0.0, 0.0, 0.0, 0.0, 0.0)),
    ],
)
def test_camera_from_info(model, d, dist):
    base = CameraModel(full_scale_counts=65535.0, count_scale=16.0, name="lab camera")
    got = camera_from_info(info(model, d), base)
    cam = got.camera
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (320, 240, 400, 410, 160, 120)
    assert_allclose(cam.dist, dist, atol=1e-6)
    assert (cam.full_scale_counts, cam.count_scale, cam.name) == (65535.0, 16.0, "lab camera")
    assert got.lens_fit_max_px < 1e-3


@pytest.mark.parametrize(
    ("model", "d", "message"),
    [
        ("equidistant", [0.1, 0, 0, 0], "distortion model 'equidistant' is not one of"),
        ("plumb_bob", [0.1, 0.0], "plumb_bob has 2 coefficients, needs 5"),
    ],
)
def test_bad_camera_info_is_named(model, d, message):
    with pytest.raises(Ros2MessageError, match=message):
        camera_from_info(info(model, d), CameraModel())
