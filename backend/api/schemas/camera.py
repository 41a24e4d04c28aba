"""The camera's settings (GET, PUT /api/camera/settings)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody


class CameraSettingsPublic(BaseModel):
    """What the camera uses, and what holds its settings now: ``locked`` says why none
    can be changed by hand (a campaign sets them per set-point), ``frequency_held`` why
    the modulation frequency cannot (a recording records); null when nothing holds them.
    A change they hold answers 409 with the same sentence."""

    integration_time_us: float
    modulation_frequency_mhz: float
    frame_rate_hz: float
    auto_exposure: bool
    unambiguous_range_mm: float
    locked: str | None = None
    frequency_held: str | None = None


class CameraSettingsUpdate(StrictBody):
    """Fields left out keep their current value."""

    integration_time_us: float | None = Field(default=None, ge=1.0, le=20000.0)
    modulation_frequency_mhz: float | None = Field(default=None, ge=1.0, le=24.0)
    frame_rate_hz: float | None = Field(default=None, ge=1.0, le=60.0)
    auto_exposure: bool | None = None
