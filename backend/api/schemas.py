"""Request and response schemas (pydantic): plain data, no behaviour. Units in every field
name (docs/architecture.md). Building them from services' types is ``presenters``' job."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic.json_schema import SkipJsonSchema


class StrictBody(BaseModel):
    """Request bodies: unknown fields, NaN/inf and values of the wrong JSON type are errors,
    not silently coerced (``true`` is not 1 deg, ``"5"`` is not a number, ``"yes"`` is not
    a boolean). Integers are accepted where a number is expected."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


# -- health and devices ------------------------------------------------------------------
class DeviceStatePublic(BaseModel):
    driver: str
    state: Literal["starting", "ok", "degraded", "stopped", "absent"]
    last_error: str | None = None
    error_count: int = 0


class HealthPublic(BaseModel):
    status: Literal["ok", "degraded"]
    version: str
    uptime_s: float
    database: Literal["ok", "error"]
    camera: DeviceStatePublic
    motion: DeviceStatePublic


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


class AxisPublic(BaseModel):
    name: str
    unit: str
    min_pos: float
    max_pos: float
    max_rate_per_s: float


class MotionPublic(DeviceStatePublic):
    axes: list[AxisPublic] = []
    positions: dict[str, float] = Field(default_factory=dict, description="encoders, deg / mm")
    targets: dict[str, float] = Field(default_factory=dict)
    busy: bool = False
    settled: bool = True
    stopped: bool = False


class DevicesPublic(BaseModel):
    camera: CameraDevicePublic
    motion: MotionPublic


# -- camera settings ---------------------------------------------------------------------
class CameraSettingsPublic(BaseModel):
    integration_time_us: float
    modulation_frequency_mhz: float
    frame_rate_hz: float
    auto_exposure: bool
    unambiguous_range_mm: float


class CameraSettingsUpdate(StrictBody):
    """Fields left out keep their current value."""

    integration_time_us: float | None = Field(None, ge=1.0, le=20000.0)
    modulation_frequency_mhz: float | None = Field(None, ge=1.0, le=24.0)
    frame_rate_hz: float | None = Field(None, ge=1.0, le=60.0)
    auto_exposure: bool | None = None


# -- pose --------------------------------------------------------------------------------
class MatchedPublic(BaseModel):
    catalog_id: int
    u_px: float
    v_px: float
    point_mm: list[float] = Field(description="measured position in the camera frame")
    distance_mm: float
    residual_mm: float
    area_px: int
    centroid_sigma_px: float | None = Field(
        None, description="predicted 1-sigma of the centroid per image axis"
    )
    range_sigma_mm: float | None = Field(None, description="predicted 1-sigma of the range")


class BlobPublic(BaseModel):
    u_px: float
    v_px: float
    distance_mm: float | None = Field(
        description="null when no pixel of the blob has a valid distance"
    )


class TruthPublic(BaseModel):
    """The lab's ground truth for this frame (encoders + nominal geometry) and the error
    of the measurement against it."""

    x_mm: float
    y_mm: float
    z_mm: float
    pitch_deg: float
    yaw_deg: float
    roll_deg: float
    position_error_mm: float | None = None
    attitude_error_deg: float | None = Field(None, description="geodesic angle")


class PosePublic(BaseModel):
    frame_index: int
    frame_time_s: float
    captured_unix_s: float
    processed_unix_s: float
    catalog: str
    ok: bool
    reason: str
    x_mm: float | None = None
    y_mm: float | None = None
    z_mm: float | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    roll_deg: float | None = None
    quaternion_wxyz: list[float] | None = None
    position_sigma_mm: list[float] | None = Field(None, description="1-sigma, x y z")
    attitude_sigma_deg: list[float] | None = Field(
        None, description="1-sigma of the rotation-vector components"
    )
    n_candidates: int
    n_matched: int
    matched: list[MatchedPublic]
    unmatched: list[BlobPublic]
    residual_mm: float | None
    iterations: int
    frames_used: int
    motion: bool
    timings_ms: dict[str, float]
    truth: TruthPublic | None = None


# -- motion ------------------------------------------------------------------------------
class MoveRequest(StrictBody):
    """Axis set-points; axes left out stay where they are. At least one is required, and
    ``null`` is not a set-point (leave the axis out instead)."""

    model_config = ConfigDict(json_schema_extra={"minProperties": 1})

    yaw_deg: float | SkipJsonSchema[None] = None
    pitch_deg: float | SkipJsonSchema[None] = None
    roll_deg: float | SkipJsonSchema[None] = None
    rail_mm: float | SkipJsonSchema[None] = None

    @model_validator(mode="before")
    @classmethod
    def _no_nulls(cls, data: object) -> object:
        if isinstance(data, dict):
            nulls = [k for k, v in data.items() if v is None]
            if nulls:
                raise ValueError(
                    f"{', '.join(nulls)}: null is not a set-point; leave the axis out to keep "
                    "it where it is"
                )
        return data

    def setpoints(self) -> dict[str, float]:
        names = {"yaw_deg": "yaw", "pitch_deg": "pitch", "roll_deg": "roll", "rail_mm": "rail"}
        return {names[k]: v for k, v in self.model_dump().items() if v is not None}


# -- catalogs ----------------------------------------------------------------------------
class ReflectorModel(StrictBody):
    id: int = Field(ge=0, le=1_000_000)
    position_mm: list[Annotated[float, Field(ge=-1e6, le=1e6)]] = Field(
        min_length=3, max_length=3, description="centre in the target frame, mm"
    )
    diameter_mm: float = Field(gt=0, le=10_000)


class CatalogCreate(StrictBody):
    name: str = Field(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    reflectors: list[ReflectorModel] = Field(min_length=3, max_length=256)


class CatalogPublic(BaseModel):
    name: str
    builtin: bool
    active: bool
    reflectors: list[ReflectorModel]


class ActiveCatalogPublic(BaseModel):
    catalog: str
