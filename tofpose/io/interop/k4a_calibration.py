"""An Azure Kinect recording's ``calibration.json`` -> the depth camera's ``CameraModel``
in the recording's depth mode.

The file (the Sensor SDK's factory calibration, attached to every recording) gives each
camera's intrinsics for its full sensor, normalised by the sensor size: in
``Intrinsics.ModelParameters`` the order of ``k4a_calibration_intrinsic_parameters_t``,
(cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1), with ``MetricRadius``
beside them. A depth mode reads a binned and cropped window of the 1024 x 1024 depth
sensor; as the SDK does it (``transformation_get_mode_specific_camera_calibration``):

    f_px = f * binned_size,   c_px = c * binned_size - crop_offset - 0.5

(the 0.5: from the corner of the top-left pixel to its centre, DESIGN's pixel origin).
The lens model ``CALIBRATION_LensDistortionModelBrownConrady`` is OpenCV's rational
model (codx = cody = 0) and is stored as the nearest five coefficients
(``distortion_fit``), fitted over the mode's field of view.

The device fields (full scale, count scale, z depth in mm codes, 0 invalid, modulation)
are those of the shipped ``azure-kinect-nfov`` profile; the range is the mode's.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile
from tofpose.io.interop.distortion_fit import DistortionFit, fit_five_coefficients

#: the profile whose device fields an Azure Kinect recording's camera takes
PROFILE = "azure-kinect-nfov"
DEPTH_LOCATION = "CALIBRATION_CameraLocationD0"
BROWN_CONRADY = "CALIBRATION_LensDistortionModelBrownConrady"


@dataclass(frozen=True)
class DepthMode:
    """One depth mode of the Azure Kinect (Sensor SDK and its hardware specification).

    binned_px : the sensor's size after binning, px; crop_px : (x, y) offset of the
    output window, px; size_px : (width, height) of the images; fov_deg : (horizontal,
    vertical) field of view; range_mm : the far end of the operating range (where the
    distance stops being reported).
    """

    binned_px: int
    crop_px: tuple[int, int]
    size_px: tuple[int, int]
    fov_deg: tuple[float, float]
    range_mm: float

    @property
    def field_radius(self) -> float:
        """hypot(tan(hfov/2), tan(vfov/2)): the undistorted radius of the field's corner."""
        h, v = (math.tan(math.radians(a) / 2.0) for a in self.fov_deg)
        return math.hypot(h, v)


#: the depth modes (``K4A_DEPTH_MODE`` of a recording's DEPTH track, without the prefix)
DEPTH_MODES: dict[str, DepthMode] = {
    "NFOV_2X2BINNED": DepthMode(512, (96, 90), (320, 288), (75.0, 65.0), 5460.0),
    "NFOV_UNBINNED": DepthMode(1024, (192, 180), (640, 576), (75.0, 65.0), 3860.0),
    "WFOV_2X2BINNED": DepthMode(512, (0, 0), (512, 512), (120.0, 120.0), 2880.0),
    "WFOV_UNBINNED": DepthMode(1024, (0, 0), (1024, 1024), (120.0, 120.0), 2210.0),
    "PASSIVE_IR": DepthMode(1024, (0, 0), (1024, 1024), (120.0, 120.0), 2210.0),
}


@dataclass(frozen=True)
class K4aCamera:
    """The depth camera of a recording: ``camera`` and the lens fit it carries."""

    camera: CameraModel
    lens_fit: DistortionFit


def depth_camera_parameters(calibration: dict) -> tuple[list[float], float, tuple[int, int]]:
    """(the 14 model parameters, MetricRadius, (SensorWidth, SensorHeight)) of the depth
    camera in a parsed ``calibration.json``; ``ValueError`` naming what is missing."""
    try:
        cameras = calibration["CalibrationInformation"]["Cameras"]
    except (KeyError, TypeError) as exc:
        raise ValueError("calibration.json has no CalibrationInformation.Cameras") from exc
    depth = [c for c in cameras if isinstance(c, dict) and c.get("Location") == DEPTH_LOCATION]
    if not depth:
        found = [c.get("Location") for c in cameras if isinstance(c, dict)]
        raise ValueError(f"calibration.json has no depth camera ({DEPTH_LOCATION}); has {found}")
    cam = depth[0]
    try:
        intrinsics = cam["Intrinsics"]
        model = intrinsics["ModelType"]
        params = [float(v) for v in intrinsics["ModelParameters"]]
        sensor = (int(cam["SensorWidth"]), int(cam["SensorHeight"]))
        radius = float(cam.get("MetricRadius", 0.0))
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"calibration.json: malformed depth camera intrinsics ({exc})") from exc
    if model != BROWN_CONRADY:
        raise ValueError(f"calibration.json: depth lens model {model!r} is not {BROWN_CONRADY}")
    if len(params) < 14:
        raise ValueError(f"calibration.json: {len(params)} depth model parameters, need 14")
    return params[:14], radius, sensor


def depth_camera(calibration_json: str | bytes, depth_mode: str) -> K4aCamera:
    """The depth (and IR) camera of an Azure Kinect recording.

    Parameters
    ----------
    calibration_json : str or bytes
        The recording's ``calibration.json`` attachment (trailing NULs allowed).
    depth_mode : str
        The DEPTH track's ``K4A_DEPTH_MODE`` (``NFOV_UNBINNED``, ...; ``DEPTH_MODES``).

    Returns
    -------
    K4aCamera
        Its camera: intrinsics of the mode in px, the lens as five coefficients fitted
        over the mode's field, the ``azure-kinect-nfov`` profile's device fields, the
        mode's range; ``distance_kind`` "z" (the device's depth). ``ValueError`` naming
        the problem for a malformed file or an unknown mode.
    """
    mode = DEPTH_MODES.get(depth_mode)
    if mode is None:
        raise ValueError(f"depth mode {depth_mode!r} is not one of {', '.join(DEPTH_MODES)}")
    text = calibration_json.decode() if isinstance(calibration_json, bytes) else calibration_json
    try:
        doc = json.loads(text.rstrip("\x00"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"calibration.json is not valid JSON ({exc})") from exc
    params, metric_radius, sensor = depth_camera_parameters(doc)
    if sensor != (1024, 1024):
        raise ValueError(f"calibration.json: depth sensor is {sensor}, expected (1024, 1024)")
    cx, cy, fx, fy, k1, k2, k3, k4, k5, k6, codx, cody, p2, p1 = params
    if codx != 0.0 or cody != 0.0:
        raise ValueError(f"calibration.json: centre of distortion ({codx}, {cody}) is not 0")
    b = mode.binned_px
    fx_px, fy_px = fx * b, fy * b
    cx_px, cy_px = cx * b - mode.crop_px[0] - 0.5, cy * b - mode.crop_px[1] - 0.5
    width, height = mode.size_px
    K = np.array([[fx_px, 0.0, cx_px], [0.0, fy_px, cy_px], [0.0, 0.0, 1.0]])
    radius = mode.field_radius if metric_radius <= 0 else min(mode.field_radius, metric_radius)
    fit = fit_five_coefficients(
        K,
        np.array([k1, k2, p1, p2, k3, k4, k5, k6]),
        width=width,
        height=height,
        field_radius=radius,
    )
    profile = load_profile(PROFILE)
    camera = replace(
        profile,
        name=f"Azure Kinect {depth_mode}",
        width=width,
        height=height,
        fx=fx_px,
        fy=fy_px,
        cx=cx_px,
        cy=cy_px,
        dist=fit.dist,
        unwrapped_range_mm=mode.range_mm,
    )
    return K4aCamera(camera=camera, lens_fit=fit)
