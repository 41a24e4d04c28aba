"""The kernels' camera model against ``tofpose.core.reference.camera`` (Eqs. 7-9 by OpenCV's
projectPoints and undistortPoints; ``CameraModel`` calls these kernels, so it is not
the reference)."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.kernels.camera import bearings, project
from tofpose.core.reference import camera as reference

LENSES = [(0.0, 0.0, 0.0, 0.0, 0.0), (-0.21, 0.08, 0.0012, -0.0007, -0.01), (0.05, 0, 0, 0, 0)]


@pytest.mark.parametrize("dist", LENSES)
def test_projection_and_bearings_are_the_camera_models(dist):
    cam = CameraModel(fx=330.0, fy=328.0, cx=161.2, cy=118.7, dist=dist)
    rng = np.random.default_rng(2)
    pts = np.column_stack(
        (rng.uniform(-800, 800, 200), rng.uniform(-600, 600, 200), rng.uniform(600, 9000, 200))
    )
    d = np.asarray(cam.dist, float)
    np.testing.assert_allclose(
        project(pts, cam.fx, cam.fy, cam.cx, cam.cy, d),
        reference.project(pts, cam.K, d),
        rtol=0,
        atol=1e-9,
    )
    uv = np.column_stack((rng.uniform(0, 319, 200), rng.uniform(0, 239, 200)))
    np.testing.assert_allclose(
        bearings(uv, cam.fx, cam.fy, cam.cx, cam.cy, d),
        reference.bearings(uv, cam.K, d),
        rtol=0,
        atol=1e-12,
    )
