"""An Azure Kinect calibration.json -> the depth camera of each depth mode (the Sensor
SDK's binning and crop of the 1024 x 1024 sensor)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tofpose.io.interop.k4a_calibration import depth_camera

#: an ideal lens (k4 = k1 cancels k1), normalised intrinsics
PARAMS = [0.5, 0.51, 0.49, 0.492, 0.3, 0, 0, 0.3, 0, 0, 0, 0, 0, 0]


def calibration(params=PARAMS, location="CALIBRATION_CameraLocationD0") -> str:
    cam = {
        "Intrinsics": {
            "ModelParameterCount": 14,
            "ModelParameters": params,
            "ModelType": "CALIBRATION_LensDistortionModelBrownConrady",
        },
        "Location": location,
        "MetricRadius": 1.74,
        "SensorWidth": 1024,
        "SensorHeight": 1024,
    }
    return json.dumps({"CalibrationInformation": {"Cameras": [cam]}}) + "\x00"


@pytest.mark.parametrize(
    ("mode", "binned", "crop", "size"),
    [
        ("NFOV_UNBINNED", 1024, (192, 180), (640, 576)),
        ("NFOV_2X2BINNED", 512, (96, 90), (320, 288)),
        ("WFOV_2X2BINNED", 512, (0, 0), (512, 512)),
        ("WFOV_UNBINNED", 1024, (0, 0), (1024, 1024)),
    ],
)
def test_mode_window(mode, binned, crop, size):
    cam = depth_camera(calibration(), mode).camera
    assert (cam.width, cam.height) == size
    assert_allclose(
        [cam.fx, cam.fy, cam.cx, cam.cy],
        [
            0.49 * binned,
            0.492 * binned,
            0.5 * binned - crop[0] - 0.5,
            0.51 * binned - crop[1] - 0.5,
        ],
    )
    assert_allclose(cam.dist, 0.0, atol=1e-6)  # the ideal lens stays ideal
    assert cam.distance_kind == "z" and cam.full_scale_counts == 65535.0


def test_p1_p2_come_from_the_end_of_the_list():
    params = [*PARAMS[:4], 0, 0, 0, 0, 0, 0, 0, 0, 3e-4, -1e-4]  # ..., p2, p1
    cam = depth_camera(calibration(params), "NFOV_UNBINNED").camera
    assert cam.dist == (0.0, 0.0, -1e-4, 3e-4, 0.0)  # OpenCV order k1, k2, p1, p2, k3
    assert np.isfinite(cam.fx)


@pytest.mark.parametrize(
    ("text", "mode", "message"),
    [
        (calibration(), "NFOV_4X4", "depth mode 'NFOV_4X4' is not one of"),
        (calibration(location="CALIBRATION_CameraLocationPV0"), "NFOV_UNBINNED", "no depth"),
        ("{", "NFOV_UNBINNED", "not valid JSON"),
        (calibration(PARAMS[:10]), "NFOV_UNBINNED", "10 depth model parameters, need 14"),
    ],
)
def test_bad_calibration_is_named(text, mode, message):
    with pytest.raises(ValueError, match=message):
        depth_camera(text, mode)
