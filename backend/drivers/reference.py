"""The lab's reference pose for cameras that do not know the truth (real devices): read the
rate table's encoders when a frame arrives and put them through the lab's nominal
geometry, exactly as the simulated lab computes its reference (docs/campaigns.md)."""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

from backend.drivers.base import CameraDriver, CameraFrame, MotionDriver
from tofpose.core.camera import CameraModel
from tofpose.sim.bench import LabGeometry

log = logging.getLogger(__name__)


class EncoderReferencedCamera:
    """Wraps a camera (implements ``CameraDriver``): each frame without a lab reference gets
    ``T_camera_target_lab = geometry.T_camera_target(encoders, nominal)`` and the encoder
    readings in ``meta["encoders"]``; its exact pose (``T_camera_target_exact``, unknown
    to a real camera) is left as the camera gave it. A failing encoder read leaves the
    frame without a reference (the frame itself is still good); everything else is the
    wrapped camera's."""

    def __init__(self, camera: CameraDriver, motion: MotionDriver, geometry: LabGeometry):
        self.camera = camera
        self.motion = motion
        self.geometry = geometry
        self.name = camera.name

    @property
    def model(self) -> CameraModel:
        """The wrapped camera's model, as it is now (it follows the camera's settings)."""
        return self.camera.model

    @model.setter
    def model(self, value: CameraModel) -> None:
        self.camera.model = value

    def read(self, timeout_s: float) -> CameraFrame:
        frame = self.camera.read(timeout_s)
        if frame.T_camera_target_lab is not None:
            return frame
        try:
            positions = self.motion.status().positions
        except Exception as exc:  # the motion link's own health reports it
            log.debug("no encoder reference for frame %d: %s", frame.index, exc)
            return frame
        T_lab = self.geometry.T_camera_target(positions, true=False)
        return replace(frame, T_camera_target_lab=T_lab, meta={**frame.meta, "encoders": positions})

    def get_settings(self):
        return self.camera.get_settings()

    def apply_settings(self, settings):
        return self.camera.apply_settings(settings)

    def close(self) -> None:
        self.camera.close()

    def __getattr__(self, name: str) -> Any:  # describe(), driver extras
        return getattr(self.camera, name)
