"""Which lab reference the live error is measured against.

The simulated lab (and a real bench through ``EncoderReferencedCamera``) gives every
frame a reference pose from the encoders and the lab's **nominal** geometry: the camera
mount and target placement as designed. A real bench differs from its drawings (the
simulated one has a mount error of about 10 mm and 0.3 deg on purpose), so against the
nominal reference the live error includes the bench's own error. A calibration campaign
(docs/campaigns.md) estimates the mount and placement; selecting that calibration here
makes the live reference ``encoders + calibrated geometry``, as reports already apply it
with ``?calibration=ID``.
"""

from __future__ import annotations

from dataclasses import dataclass

from backend.drivers.base import CameraFrame
from backend.services.calibrations import transform
from tofpose.core.geometry import RigidTransform
from tofpose.lab.kinematics import camera_target

NOMINAL_LABEL = "nominal lab geometry (uncalibrated)"
AXES = ("yaw", "pitch", "roll", "rail")


@dataclass(frozen=True)
class LiveReference:
    """The nominal reference (``calibration_id`` None) or a calibration's mount and
    placement (4 x 4 ``T_inner_camera`` and ``T_lab_target``, mm)."""

    calibration_id: int | None = None
    calibration_name: str = ""
    mount: RigidTransform | None = None
    placement: RigidTransform | None = None

    @classmethod
    def from_calibration(cls, row) -> LiveReference:
        """From a stored ``CalibrationRow`` (its mount and placement matrices)."""
        return cls(row.id, row.name, transform(row.mount), transform(row.placement))

    @property
    def label(self) -> str:
        if self.calibration_id is None:
            return NOMINAL_LABEL
        return f"calibration {self.calibration_id} ({self.calibration_name!r})"

    def pose(self, frame: CameraFrame) -> RigidTransform | None:
        """``T_camera_target`` of the reference for this frame, or None when the frame has
        none (nominal: the frame's ``T_camera_target_lab``, never its exact pose; for a
        calibration, None without an encoder reading of every axis)."""
        if self.calibration_id is None or self.mount is None or self.placement is None:
            return frame.T_camera_target_lab  # nominal (a calibration has both transforms)
        encoders = frame.meta.get("encoders") or {}
        if not set(AXES) <= set(encoders):
            return None
        return camera_target({a: float(encoders[a]) for a in AXES}, self.mount, self.placement)
