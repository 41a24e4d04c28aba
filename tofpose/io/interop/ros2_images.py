"""Decoded ROS 2 ``sensor_msgs`` messages -> our arrays and camera (the ROS 2 import;
docs/interop.md, "ROS 2 in").

Pure conversions of messages as ``rosbags`` deserialises them (attribute access; ``data``
a uint8 array), no I/O. ROS's conventions (REP 118 for depth images): ``16UC1`` depth in
mm with 0 for no return, ``32FC1`` depth in m with NaN (or 0, or +-Inf) for none; rows
``step`` bytes apart, ``is_bigendian`` saying the byte order. A ``CameraInfo``'s K and D
(``plumb_bob``: OpenCV's five; ``rational_polynomial``: eight, stored as the nearest five,
``distortion_fit``) are the camera's, at the size it states.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.io.interop.distortion_fit import fit_five_coefficients

#: amplitude / IR image encodings and their pixel types (byte order from ``is_bigendian``)
AMPLITUDE_ENCODINGS: dict[str, str] = {"mono16": "u2", "16UC1": "u2", "mono8": "u1", "8UC1": "u1"}
#: depth image encodings: pixel type and millimetres per unit
DEPTH_ENCODINGS: dict[str, tuple[str, float]] = {"16UC1": ("u2", 1.0), "32FC1": ("f4", 1000.0)}
#: CameraInfo distortion models read, and how many coefficients each has
DISTORTION_MODELS: dict[str, int] = {"plumb_bob": 5, "rational_polynomial": 8}


class Ros2MessageError(ValueError):
    """A message that cannot be read as an image or a camera: says which field and why."""


def image_pixels(msg, dtype: str) -> np.ndarray:
    """The (H, W) pixels of a ``sensor_msgs/msg/Image`` as ``dtype`` (e.g. "u2") in the
    machine's byte order, rows ``step`` bytes apart; ``Ros2MessageError`` when the data is
    shorter than ``height * step`` or a row shorter than ``width`` pixels."""
    dt = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if h <= 0 or w <= 0 or step < w * dt.itemsize or data.size < h * step:
        raise Ros2MessageError(
            f"{msg.encoding} image of {w} x {h} has {data.size} bytes with step {step} "
            f"(needs step >= {w * dt.itemsize} and {h} rows)"
        )
    rows = data[: h * step].reshape(h, step)[:, : w * dt.itemsize]
    return np.ascontiguousarray(rows).view(dt).reshape(h, w).astype(dt.newbyteorder("="))


def amplitude_counts(msg) -> np.ndarray:
    """An amplitude / IR ``Image`` -> (H, W) uint16 counts, values unchanged.

    ``Ros2MessageError`` naming the encoding when it is not one of
    ``AMPLITUDE_ENCODINGS``."""
    dtype = AMPLITUDE_ENCODINGS.get(msg.encoding)
    if dtype is None:
        raise Ros2MessageError(
            f"amplitude image encoding {msg.encoding!r} is not one of "
            f"{', '.join(AMPLITUDE_ENCODINGS)}"
        )
    return image_pixels(msg, dtype).astype(np.uint16)


def depth_mm(msg) -> np.ndarray:
    """A depth ``Image`` (REP 118) -> (H, W) float32 mm, NaN where there is no depth
    (0, NaN, +-Inf). ``Ros2MessageError`` naming an encoding not in ``DEPTH_ENCODINGS``."""
    spec = DEPTH_ENCODINGS.get(msg.encoding)
    if spec is None:
        raise Ros2MessageError(
            f"depth image encoding {msg.encoding!r} is not one of {', '.join(DEPTH_ENCODINGS)}"
        )
    dtype, mm_per_unit = spec
    values = image_pixels(msg, dtype).astype(np.float64)
    invalid = ~np.isfinite(values) | (values <= 0)
    return np.where(invalid, np.nan, values * mm_per_unit).astype(np.float32)


@dataclass(frozen=True)
class Ros2Camera:
    """A ``CameraInfo``'s camera, and the largest pixel error of its lens as five
    coefficients (0 for ``plumb_bob``: exact)."""

    camera: CameraModel
    lens_fit_max_px: float


def _corner_radius(K: np.ndarray, dist8: np.ndarray, width: int, height: int) -> float:
    """The largest undistorted radius hypot(x/z, y/z) of the image's corner pixels."""
    corners = np.array(
        [[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]]
    )
    xy = cv2.undistortPoints(corners.reshape(-1, 1, 2), K, dist8).reshape(-1, 2)
    return float(np.hypot(xy[:, 0], xy[:, 1]).max())


def camera_from_info(msg, base: CameraModel) -> Ros2Camera:
    """The camera of a ``sensor_msgs/msg/CameraInfo``: size, K and D from the message,
    every device field (full scale, count scale, modulation, range, name) from ``base``
    (a profile), ``distance_kind`` "radial" (what the importer stores).

    ``Ros2MessageError`` for an uncalibrated camera (K all zero), a distortion model not
    in ``DISTORTION_MODELS`` or a coefficient count that does not match it."""
    K = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    w, h = int(msg.width), int(msg.height)
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise Ros2MessageError("CameraInfo has no K (fx, fy not positive: an uncalibrated camera)")
    d = [float(v) for v in msg.d]
    model = msg.distortion_model
    if not d:  # no distortion stated: an ideal (or rectified) camera
        model, d = "plumb_bob", [0.0] * 5
    n = DISTORTION_MODELS.get(model)
    if n is None:
        raise Ros2MessageError(
            f"CameraInfo distortion model {model!r} is not one of {', '.join(DISTORTION_MODELS)}"
        )
    if len(d) != n:
        raise Ros2MessageError(f"CameraInfo {model} has {len(d)} coefficients, needs {n}")
    fit_px = 0.0
    if n == 8 and any(d[5:]):
        dist8 = np.asarray(d)
        fit = fit_five_coefficients(
            K, dist8, width=w, height=h, field_radius=_corner_radius(K, dist8, w, h)
        )
        dist, fit_px = fit.dist, fit.max_error_px
    else:
        k1, k2, p1, p2, k3 = d[:5]
        dist = (k1, k2, p1, p2, k3)
    camera = replace(
        base,
        width=w,
        height=h,
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=dist,
        distance_kind="radial",
    )
    return Ros2Camera(camera=camera, lens_fit_max_px=fit_px)
