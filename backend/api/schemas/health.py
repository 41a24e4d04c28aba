"""GET /api/health."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel

from backend.api.schemas.common import DeviceStatePublic, PipelineStatePublic


class HealthPublic(BaseModel):
    status: Literal["ok", "degraded"]
    version: str
    uptime_s: float
    database: Literal["ok", "error"]
    camera: DeviceStatePublic
    motion: DeviceStatePublic
    pipeline: PipelineStatePublic
