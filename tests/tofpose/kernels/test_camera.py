"""The kernels' camera model against OpenCV's projectPoints and undistortPoints
(``CameraModel`` calls these kernels, so it is not the reference)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tofpose.camera import CameraModel
from tofpose.kernels.camera import bearings, project

LENSES = [(0.0, 0.0, 0.0, 0.0, 0.0), (-0.21, 0.08, 0.0012, -0.0007, -0.01), (0.05, 0, 0, 0, 0)]


@pytest.mark.parametrize("dist", LENSES)
def test_projection_and_bearings_are_the_camera_models(dist):
    cam = CameraModel(fx=330.0, fy=328.0, cx=161.2, cy=118.7, dist=dist)
    rng = np.random.default_rng(2)
    pts = np.column_stack((rng.uniform(-800, 800, 200), rng.uniform(-600, 600, 200),
                           rng.uniform(600, 9000, 200)))  # fmt: skip
    d = np.asarray(cam.dist, float)
    opencv_uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, d)
    np.testing.assert_allclose(project(pts, cam.fx, cam.fy, cam.cx, cam.cy, d),
                               opencv_uv.reshape(-1, 2), rtol=0, atol=1e-9)  # fmt: skip
    uv = np.column_stack((rng.uniform(0, 319, 200), rng.uniform(0, 239, 200)))
    xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, d).reshape(-1, 2)
    opencv_e = np.column_stack((xy, np.ones(len(xy))))
    opencv_e /= np.linalg.norm(opencv_e, axis=1, keepdims=True)
    np.testing.assert_allclose(bearings(uv, cam.fx, cam.fy, cam.cx, cam.cy, d),
                               opencv_e, rtol=0, atol=1e-12)  # fmt: skip
