"""GET /api/devices: the camera, the motion system and the live pipeline."""

from __future__ import annotations

from pydantic import BaseModel, Field

from backend.api.schemas.common import DeviceStatePublic, PipelineStatePublic
from backend.api.schemas.motion import MotionPublic


class CameraDevicePublic(DeviceStatePublic):
    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    frames_processed: int
    frame_rate_hz: float = Field(description="delivered rate over the last few frames")
    catalog: str


class DevicesPublic(BaseModel):
    camera: CameraDevicePublic
    motion: MotionPublic
    pipeline: PipelineStatePublic
