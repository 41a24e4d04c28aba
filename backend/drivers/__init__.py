"""Device drivers: camera and motion Protocols and their implementations."""

from backend.drivers.base import (
    AxisLimits,
    CameraDriver,
    CameraError,
    CameraFrame,
    CameraSettings,
    MotionDriver,
    MotionError,
    MotionStatus,
)

__all__ = [
    "AxisLimits",
    "CameraDriver",
    "CameraError",
    "CameraFrame",
    "CameraSettings",
    "MotionDriver",
    "MotionError",
    "MotionStatus",
]
