"""Request and response schemas (pydantic): plain data, no behaviour. Units in every field
name (docs/architecture.md). Building them from services' types is ``presenters``' job."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import (
    AwareDatetime,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    model_validator,
)
from pydantic.json_schema import SkipJsonSchema

from backend.services.campaigns.campaign_states import CampaignCommand, CampaignState


class StrictBody(BaseModel):
    """Request bodies: unknown fields, NaN/inf and values of the wrong JSON type are errors,
    not silently coerced (``true`` is not 1 deg, ``"5"`` is not a number, ``"yes"`` is not
    a boolean). Integers are accepted where a number is expected."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


def _integral_float_to_int(value: object) -> object:
    """JSON Schema's ``integer`` includes ``5.0``: take it as 5 (``5.5``, ``"5"`` and
    ``true`` stay errors under strict validation)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


JsonInt = Annotated[int, BeforeValidator(_integral_float_to_int)]
"""An integer as JSON Schema means it (strict otherwise)."""
RowId = Annotated[int, Field(ge=1, le=2**31 - 1), BeforeValidator(_integral_float_to_int)]
"""A stored row's id (constraints before the validator: pydantic writes them into the
schema as minimum/maximum only in this order)."""


# -- health and devices ------------------------------------------------------------------
class DeviceStatePublic(BaseModel):
    driver: str
    state: Literal["starting", "ok", "degraded", "stopped", "absent"]
    last_error: str | None = None
    error_count: int = 0
    model: str | None = Field(None, description="device model as the device reports it")
    firmware: str | None = Field(None, description="firmware or software version")
    link: Literal["up", "down"] | None = Field(
        None, description="connection to the device (real devices and their emulators)"
    )
    address: str | None = Field(None, description="where the device is reached")


class PipelineStatePublic(BaseModel):
    """The live pipeline's compiled kernels: compiled in the background at server start
    (about 1-2 min after an install, seconds from numba's cache); meanwhile the poses come
    from the pipeline's reference implementation (NumPy/SciPy, the same poses to ~0.01
    mm), then from the compiled one."""

    state: Literal["compiling", "ready", "failed"] = Field(
        description="the kernels' warm-up: compiling, ready, or failed (the poses then "
        "stay with the reference implementation)"
    )
    implementation: Literal["reference", "compiled"] | None = Field(
        description="which implementation of the pipeline measures the live frames: "
        "'reference' while the kernels compile, 'compiled' once they are ready; null in "
        "the warm-up's first second, when frames stream without a pose"
    )
    seconds: float = Field(description="since the warm-up started, or how long it took")
    detail: str = ""


class HealthPublic(BaseModel):
    status: Literal["ok", "degraded"]
    version: str
    uptime_s: float
    database: Literal["ok", "error"]
    camera: DeviceStatePublic
    motion: DeviceStatePublic
    pipeline: PipelineStatePublic


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
    max_accel_per_s2: float | None = Field(
        None,
        description="acceleration limit; null when the motion system does not report "
        "one (then it runs no profiles on that axis)",
    )


class ProfilePublic(BaseModel):
    """The motion profile running now (POST /api/motion/profile)."""

    axis: str
    kind: Literal["sine", "ramp"]
    elapsed_s: float
    remaining_s: float
    duration_s: float = Field(description="the whole profile, fades and ramps included")


class MotionPublic(DeviceStatePublic):
    axes: list[AxisPublic] = []
    positions: dict[str, float] = Field(default_factory=dict, description="encoders, deg / mm")
    time_s: float | None = Field(
        None,
        description="when the encoders were read, s, on the clock of the camera's "
        "frames where the motion system shares it (the simulated lab), else the server's "
        "monotonic clock",
    )
    targets: dict[str, float] = Field(default_factory=dict)
    busy: bool = False
    settled: bool = True
    stopped: bool = False
    profile: ProfilePublic | None = Field(None, description="the profile running, if any")
    owner_campaign_id: int | None = Field(
        None,
        description="the campaign that owns the motion system while it runs (manual "
        "moves and jogs are refused with 409 then); null when it is free",
    )
    owner_campaign_name: str | None = None
    stop_latched: bool = Field(
        False,
        description="a person's STOP holds the motion system: every move, jog, profile and "
        "campaign is refused until POST /api/motion/release (or a campaign's resume)",
    )
    stop_latched_at: str | None = Field(None, description="when that STOP was pressed (UTC)")


class DevicesPublic(BaseModel):
    camera: CameraDevicePublic
    motion: MotionPublic
    pipeline: PipelineStatePublic


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


class RejectedBlobPublic(BaseModel):
    """A bright component of the active pixel set that is not a candidate reflector."""

    u_px: float = Field(description="centre of its bounding box")
    v_px: float
    diameter_px: float = Field(description="equivalent diameter of its area")
    reason: Literal["border", "dim", "size", "oversize", "nlog", "shape", "penalty", "rank"]
    reason_text: str = Field(description="the gate that refused it, in words")


class TruthPublic(BaseModel):
    """The lab's reference for this frame (encoders + nominal geometry, or + a selected
    calibration's mount and placement) and the error of the measurement against it."""

    x_mm: float
    y_mm: float
    z_mm: float
    pitch_deg: float
    yaw_deg: float
    roll_deg: float
    position_error_mm: float | None = None
    attitude_error_deg: float | None = Field(None, description="geodesic angle")
    reference: str = Field(
        "nominal lab geometry (uncalibrated)",
        description="which reference: the nominal lab geometry, or a calibration "
        "(PUT /api/reference)",
    )


class PosePublic(BaseModel):
    """One processed frame. ``pitch_deg``, ``yaw_deg``, ``roll_deg`` are the attitude as
    people read it: Euler angles of ``R_camera_target @ diag(1, -1, -1)`` (a target facing
    the camera reads 0, 0, 0); ``quaternion_wxyz`` is the raw ``R_camera_target``."""

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
        None,
        description="1-sigma of pitch, yaw and roll (deg), propagated from the rotation-"
        "vector covariance through the Euler angles' derivative (large near gimbal lock)",
    )
    n_candidates: int
    n_matched: int
    matched: list[MatchedPublic]
    unmatched: list[BlobPublic]
    rejected: list[RejectedBlobPublic] = Field(
        default_factory=list, description="components refused by a gate (at most 50)"
    )
    active_threshold_counts: float | None = Field(
        None,
        description="I_t as applied: the active pixel set is the pixels with gray >= this",
    )
    residual_mm: float | None
    mode: Literal["acquisition", "tracking"] = Field(
        "acquisition",
        description="acquisition: the full pass; tracking: windows around the reflectors "
        "predicted from the last pose",
    )
    iterations: int
    frames_used: int
    motion: bool
    timings_ms: dict[str, float]
    truth: TruthPublic | None = None
    filter_status: Literal["initialised", "updated", "rejected", "reset", "predicted"] | None = (
        Field(
            None,
            description="what the relative-state filter did with this frame: started from "
            "its pose (initialised), fused it (updated), refused it as inconsistent with the "
            "motion so far (rejected), restarted after rejections that agree (reset), or "
            "predicted without a pose (predicted); null before its first pose",
        )
    )
    angular_rate_deg_s: list[float] | None = Field(
        None, description="the target's angular rate, camera frame (x y z), deg/s"
    )
    angular_rate_target_deg_s: list[float] | None = Field(
        None, description="the same rate in the target frame (x y z), deg/s"
    )
    angular_rate_sigma_deg_s: list[float] | None = Field(
        None, description="1-sigma of angular_rate_deg_s"
    )
    velocity_mm_s: list[float] | None = Field(
        None, description="the target origin's velocity, camera frame (x y z), mm/s"
    )
    velocity_sigma_mm_s: list[float] | None = Field(None, description="1-sigma of velocity_mm_s")


# -- 3-D scene ---------------------------------------------------------------------------
class ScenePublic(BaseModel):
    """The viser 3-D scene served by this process on a port of its own."""

    running: bool
    port: int | None = Field(None, description="the scene's port on this server's host")
    paused: bool = False
    reason: str = Field("", description="why the scene does not run (empty when it does)")
    updates: int = Field(0, description="scene updates since start")
    last_frame_index: int | None = None


class SceneUpdate(StrictBody):
    paused: bool


class FoxglovePublic(BaseModel):
    """The live Foxglove WebSocket server (``foxglove-sdk``) run by this process."""

    running: bool
    url: str | None = Field(None, description="ws:// address for the Foxglove app")
    port: int | None = None
    reason: str = Field("", description="why it does not run (empty when it does)")
    published: int = Field(0, description="frames published to subscribed clients")
    dropped: int = Field(
        0,
        description="frames skipped because the publisher was still busy with one "
        "(the camera loop never waits for it)",
    )


# -- motion ------------------------------------------------------------------------------
class AxisBody(StrictBody):
    """Axis set-points (yaw, pitch, roll in deg, rail in mm); an axis left out stays where
    it is. At least one is required, and ``null`` is not a set-point."""

    model_config = ConfigDict(json_schema_extra={"minProperties": 1})

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

    @model_validator(mode="after")
    def _at_least_one(self):
        if not self.axes():
            raise ValueError("give at least one of yaw_deg, pitch_deg, roll_deg, rail_mm")
        return self

    def axes(self) -> dict[str, float]:
        """{"yaw": deg, "rail": mm, ...} of the axes given."""
        return {k.rsplit("_", 1)[0]: v for k, v in self.model_dump().items() if v is not None}


class MoveRequest(AxisBody):
    """A manual move; refused with 409 while a campaign owns the motion system."""

    yaw_deg: float | SkipJsonSchema[None] = None
    pitch_deg: float | SkipJsonSchema[None] = None
    roll_deg: float | SkipJsonSchema[None] = None
    rail_mm: float | SkipJsonSchema[None] = None


JOG_MAX_DEG = 10.0
JOG_MAX_MM = 1000.0
"""The largest single jog step: a jog is a nudge, a larger move is a go-to."""


JogDeg = Annotated[
    float,
    Field(
        ge=-JOG_MAX_DEG,
        le=JOG_MAX_DEG,
        description="signed step, deg (not 0)",
        json_schema_extra={"not": {"const": 0}},
    ),
]
JogMm = Annotated[
    float,
    Field(
        ge=-JOG_MAX_MM,
        le=JOG_MAX_MM,
        description="signed step, mm (not 0)",
        json_schema_extra={"not": {"const": 0}},
    ),
]


class JogRequest(AxisBody):
    """A relative move of exactly one axis (deg for yaw, pitch, roll; mm for rail),
    applied by the server to that axis' encoder position when the request arrives (never
    to a position a client last saw). Refused with 409 while the motion system is moving
    or a campaign owns it, and with 422 when the step would leave the soft limits from
    where the axis is now."""

    model_config = ConfigDict(json_schema_extra={"minProperties": 1, "maxProperties": 1})
    # AxisBody's checks apply: null is not a step, at least one axis is given

    yaw_deg: JogDeg | SkipJsonSchema[None] = None
    pitch_deg: JogDeg | SkipJsonSchema[None] = None
    roll_deg: JogDeg | SkipJsonSchema[None] = None
    rail_mm: JogMm | SkipJsonSchema[None] = None

    @model_validator(mode="after")
    def _one_real_step(self):
        steps = {k: v for k, v in self.model_dump().items() if v is not None}
        if len(steps) != 1:
            raise ValueError(
                "give exactly one of yaw_deg, pitch_deg, roll_deg, rail_mm "
                f"(got {', '.join(steps) or 'none'})"
            )
        ((name, step),) = steps.items()
        if step == 0:
            raise ValueError(f"{name}: a jog of 0 moves nothing")
        return self

    def axis_step(self) -> tuple[str, float]:
        """(axis name, step in its unit) of the one axis given."""
        ((name, step),) = {k: v for k, v in self.model_dump().items() if v is not None}.items()
        return name.rsplit("_", 1)[0], step


PROFILE_MAX_S = 3600.0
"""The longest profile phase taken (a sine's period, a ramp's hold)."""
ProfileAxis = Literal["yaw", "pitch", "roll"]


class SineProfileRequest(StrictBody):
    """A sine slew about the axis' position when the request arrives: angle = start +
    amplitude_deg * e(t) * sin(2 pi t / period_s), the envelope e fading in over the first
    period and out over the last (raised cosine), full amplitude for ``cycles`` periods
    between, so the whole profile lasts (cycles + 2) * period_s and starts and ends at
    rest. Peak rate amplitude_deg * 2 pi / period_s; peak acceleration about 5 % above
    amplitude_deg * (2 pi / period_s)^2."""

    axis: ProfileAxis
    kind: Literal["sine"]
    amplitude_deg: float = Field(gt=0, le=180.0, description="either side of the start, deg")
    period_s: float = Field(ge=0.1, le=PROFILE_MAX_S)
    cycles: JsonInt = Field(1, ge=1, le=1000, description="periods at full amplitude")


class RampProfileRequest(StrictBody):
    """A constant-rate slew from the axis' position when the request arrives: the rate
    rises to rate_deg_s at accel_deg_s2, holds for hold_s and falls back to rest at
    accel_deg_s2 (travel rate_deg_s * (hold_s + |rate_deg_s| / accel_deg_s2))."""

    axis: ProfileAxis
    kind: Literal["ramp"]
    rate_deg_s: float = Field(
        ge=-1000.0,
        le=1000.0,
        description="signed rate, deg/s (not 0)",
        json_schema_extra={"not": {"const": 0}},
    )
    hold_s: float = Field(ge=0.0, le=PROFILE_MAX_S, description="time at the constant rate")
    accel_deg_s2: Annotated[float, Field(gt=0, le=10_000.0)] | SkipJsonSchema[None] = Field(
        None,
        description="default: the axis' acceleration limit (leave it out; null is not "
        "an acceleration)",
    )

    @model_validator(mode="before")
    @classmethod
    def _no_null(cls, data: object) -> object:
        if isinstance(data, dict) and "accel_deg_s2" in data and data["accel_deg_s2"] is None:
            raise ValueError(
                "accel_deg_s2: null is not an acceleration; leave it out for the axis' limit"
            )
        return data

    @model_validator(mode="after")
    def _moves(self):
        if self.rate_deg_s == 0:
            raise ValueError("rate_deg_s: a ramp at 0 deg/s moves nothing")
        return self


ProfileRequest = Annotated[SineProfileRequest | RampProfileRequest, Field(discriminator="kind")]
"""POST /api/motion/profile: a sine or a ramp, told apart by ``kind``."""


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


# -- campaigns ---------------------------------------------------------------------------
MAX_SETPOINTS = 5000
MAX_FRAMES_PER_POINT = 100_000
MAX_FRAMES_PER_CAMPAIGN = 1_000_000
AngleDeg = Annotated[float, Field(ge=-360.0, le=360.0)]
RailMm = Annotated[float, Field(ge=0.0, le=100_000.0)]


class SetPointModel(AxisBody):
    """Axis set-points of one campaign point; an axis left out stays where it is."""

    yaw_deg: AngleDeg | SkipJsonSchema[None] = None
    pitch_deg: AngleDeg | SkipJsonSchema[None] = None
    roll_deg: AngleDeg | SkipJsonSchema[None] = None
    rail_mm: RailMm | SkipJsonSchema[None] = None


class Requirements(StrictBody):
    """Accuracy requirements per axis (default: the paper's, §6.4): a set-point passes an
    axis when the largest |error| after singular-point removal is within it."""

    x_mm: float = Field(6.0, gt=0, le=1e5)
    y_mm: float = Field(6.0, gt=0, le=1e5)
    z_mm: float = Field(28.3, gt=0, le=1e5)
    pitch_deg: float = Field(0.15, gt=0, le=180)
    yaw_deg: float = Field(0.15, gt=0, le=180)
    roll_deg: float = Field(0.15, gt=0, le=180)


AxisValues = Annotated[list[AngleDeg], Field(min_length=1, max_length=200)]


class GridGenerator(StrictBody):
    kind: Literal["grid"]
    yaw_deg: AxisValues | None = None
    pitch_deg: AxisValues | None = None
    roll_deg: AxisValues | None = None
    rail_mm: Annotated[list[RailMm], Field(min_length=1, max_length=200)] | None = None


class RangeSweepGenerator(StrictBody):
    kind: Literal["range_sweep"]
    rail_start_mm: RailMm
    rail_stop_mm: RailMm
    points: int = Field(ge=2, le=MAX_SETPOINTS)
    yaw_deg: AngleDeg | None = None
    pitch_deg: AngleDeg | None = None
    roll_deg: AngleDeg | None = None


class StabilityGenerator(StrictBody):
    kind: Literal["stability"]
    yaw_deg: AngleDeg | None = None
    pitch_deg: AngleDeg | None = None
    roll_deg: AngleDeg | None = None
    rail_mm: RailMm | None = None


class AttitudeStepsGenerator(StrictBody):
    kind: Literal["attitude_steps"]
    axis: Literal["yaw", "pitch", "roll"]
    steps_deg: Annotated[list[AngleDeg], Field(min_length=1, max_length=MAX_SETPOINTS)]
    yaw_deg: AngleDeg | None = None
    pitch_deg: AngleDeg | None = None
    roll_deg: AngleDeg | None = None
    rail_mm: RailMm | None = None


class CalibrationGenerator(StrictBody):
    kind: Literal["calibration"]
    rails_mm: Annotated[list[RailMm], Field(min_length=2, max_length=20)]
    amplitude_deg: float = Field(8.0, gt=0, le=45)


class ProfileGenerator(StrictBody):
    """A dynamic campaign (docs/campaigns.md, "Dynamic campaigns"): at each start point
    (every combination of the axis values given, yaw outermost; the profile's own axis
    at 0 deg unless given), the table settles, rests ``rest_s``, runs ``profile`` from
    there and rests ``rest_s`` again. Every frame of the three phases is stored, flagged
    in_motion while the profile ran, with the encoders interpolated to its capture time;
    ``frames_per_point`` does not apply. Each profile is checked against the soft, rate
    and acceleration limits from its start point before anything is stored."""

    kind: Literal["profile"]
    profile: ProfileRequest
    rest_s: float = Field(2.0, ge=0.5, le=600.0, description="rest before and after, s")
    yaw_deg: AxisValues | None = None
    pitch_deg: AxisValues | None = None
    roll_deg: AxisValues | None = None
    rail_mm: Annotated[list[RailMm], Field(min_length=1, max_length=200)] | None = None


Generator = Annotated[
    GridGenerator
    | RangeSweepGenerator
    | StabilityGenerator
    | AttitudeStepsGenerator
    | CalibrationGenerator
    | ProfileGenerator,
    Field(discriminator="kind"),
]


class CampaignCreate(StrictBody):
    """A campaign: explicit ``setpoints`` or a ``generator`` (exactly one of them)."""

    # "Exactly one of them" in the document too: a oneOf of the two alternatives (one
    # given, the other absent or null), so that generated clients and schemathesis know
    # that both, or neither, is invalid. The route still answers either with 422.
    model_config = ConfigDict(
        json_schema_extra={
            "oneOf": [
                {
                    "required": ["setpoints"],
                    "properties": {"setpoints": {"type": "array"}, "generator": {"type": "null"}},
                },
                {
                    "required": ["generator"],
                    "properties": {
                        "generator": {"type": "object", "additionalProperties": True},
                        "setpoints": {"type": "null"},
                    },
                },
            ]
        }
    )

    name: str = Field(min_length=1, max_length=200, pattern=r"^[^\x00-\x1f]+$")
    catalog: str = Field("paper-target", min_length=1, max_length=128)
    frames_per_point: int = Field(30, ge=1, le=MAX_FRAMES_PER_POINT)
    settle_s: float = Field(1.0, ge=0.0, le=3600.0)
    lock_timeout_s: float = Field(5.0, gt=0.0, le=3600.0)
    setpoints: (
        Annotated[list[SetPointModel], Field(min_length=1, max_length=MAX_SETPOINTS)] | None
    ) = None
    generator: Generator | None = None
    requirements: Requirements = Field(default_factory=Requirements)
    camera: CameraSettingsUpdate | None = None
    record_raw: bool = Field(
        False,
        description="keep every measured frame pair in an HDF5 recording "
        "(GET /api/campaigns/{id}/recording.h5), so the campaign can be re-processed",
    )
    notes: str = Field("", max_length=4000)


def _iso_text(v: object) -> object:
    """A date-time in JSON is ISO 8601 text (not a number of seconds)."""
    if v is not None and not isinstance(v, str | datetime):
        raise ValueError("must be an ISO 8601 date-time with a time zone, as text")
    return v


class CampaignStart(StrictBody):
    """Start now (``at`` left out) or at a given time (ISO 8601 with a time zone).

    While another campaign owns the motion system, starting now is refused (409) unless
    ``queue`` is true: then this one runs when the other finishes."""

    at: Annotated[AwareDatetime, BeforeValidator(_iso_text)] | None = Field(None, strict=False)
    queue: bool = False


class ProgressPublic(BaseModel):
    campaign_id: int
    name: str
    status: CampaignState
    setpoint_index: int = Field(description="0-based index of the set-point in progress")
    n_setpoints: int
    n_done: int
    frames_collected: int = Field(description="frames of the set-point in progress")
    frames_per_point: int
    elapsed_s: float
    eta_s: float | None


class SetPointPublic(BaseModel):
    index: int
    yaw_deg: float | None
    pitch_deg: float | None
    roll_deg: float | None
    rail_mm: float | None
    profile: dict | None = Field(
        None,
        description="a dynamic set-point's motion profile (axis, kind, its fields, "
        "rest_s), null at a static one",
    )
    status: Literal["pending", "done"]


class CampaignPublic(BaseModel):
    id: int
    name: str
    status: CampaignState
    status_reason: str
    catalog: str
    frames_per_point: int
    settle_s: float
    lock_timeout_s: float
    requirements: Requirements
    generator: dict | None
    camera: dict | None
    record_raw: bool
    notes: str
    created_at: datetime
    scheduled_at: datetime | None
    started_at: datetime | None
    finished_at: datetime | None
    n_setpoints: int
    n_done: int
    estimated_duration_s: float
    progress: ProgressPublic | None = None
    setpoints: list[SetPointPublic] | None = None


class CampaignTransitionPublic(BaseModel):
    """``command`` is accepted in ``from_state`` and leads to ``to_state``."""

    from_state: CampaignState
    command: CampaignCommand
    to_state: CampaignState


class CampaignStatesPublic(BaseModel):
    """The campaign state machine (docs/campaigns.md, "States"): what a person's commands
    do in each state. A command not listed for a state answers 409. The scheduler and
    the runner move a campaign on their own: queued -> running -> done, failed, paused,
    cancelled or interrupted."""

    states: list[CampaignState]
    finished: list[CampaignState] = Field(description="states nothing leads out of")
    transitions: list[CampaignTransitionPublic]


class MeasurementPublic(BaseModel):
    setpoint_index: int
    frame_index: int
    time_s: float
    ok: bool
    reason: str
    n_matched: int
    residual_mm: float | None
    x_mm: float | None
    y_mm: float | None
    z_mm: float | None
    pitch_deg: float | None
    yaw_deg: float | None
    roll_deg: float | None
    truth: dict[str, float] | None = Field(description="pose that produced the frame")
    lab_truth: dict[str, float] | None = Field(description="encoders + nominal geometry")
    encoders: dict[str, float] | None
    in_motion: bool | None = Field(
        None,
        description="taken while the set-point's motion profile ran (null at a static set-point)",
    )


class MeasurementPage(BaseModel):
    total: int
    offset: int
    items: list[MeasurementPublic]


# -- calibrations ------------------------------------------------------------------------
class ReferencePublic(BaseModel):
    """The live reference: nominal lab geometry, or a stored calibration."""

    source: Literal["nominal", "calibration"]
    label: str
    calibration_id: int | None = None
    n_calibrations: int = Field(description="stored calibrations that could be selected")
    calibrated_available: bool = Field(
        description="whether this lab can run a calibration campaign (its nominal geometry "
        "is known: the simulated lab)"
    )


class ReferenceUpdate(StrictBody):
    calibration_id: RowId | None = Field(
        description="a stored calibration's id, or null for the nominal lab geometry"
    )


class CalibrationCreate(StrictBody):
    """Estimate the camera mount and target placement from a finished campaign (best one
    made with the ``calibration`` generator)."""

    campaign_id: JsonInt = Field(ge=1, le=2**31 - 1)
    name: str = Field(min_length=1, max_length=200, pattern=r"^[^\x00-\x1f]+$")


class TransformPublic(BaseModel):
    matrix: list[list[float]] = Field(description="4 x 4 homogeneous, mm")
    euler_deg: list[float] = Field(description="(pitch, yaw, roll) of the rotation")
    translation_mm: list[float]


class CalibrationPublic(BaseModel):
    id: int
    name: str
    campaign_id: int | None
    created_at: datetime
    mount: TransformPublic = Field(description="T_inner_camera: the camera on the inner axis")
    placement: TransformPublic = Field(description="T_lab_target: the target in the lab")
    mount_sigma_deg: list[float]
    mount_sigma_mm: list[float]
    placement_sigma_deg: list[float]
    placement_sigma_mm: list[float]
    residual_rms_mm: float
    residual_rms_deg: float
    chi2_per_dof: float
    n_observations: int


# -- accuracy studies (tofpose.study; docs/scaleout.md) -----------------------------------
RangeM = Annotated[float, Field(ge=0.3, le=20.0)]
AttitudeDeg = Annotated[float, Field(ge=0.0, le=60.0)]
OffsetFraction = Annotated[float, Field(ge=0.0, le=0.9)]
AmbientLux = Annotated[float, Field(ge=0.0, le=150_000.0)]


# tofpose.sim.randomise.FAMILIES (tests/backend/api/test_schemas.py keeps them equal)
PhysicsFamily = Literal[
    "ideal", "grey plate", "lens blur", "gains", "systematic", "background", "all"
]


class StudyGrid(StrictBody):
    """The study's axes (each a list; every combination is a cell). Omitted axes take
    one value: 3 m, +-20 deg, 0.5 of the half field of view, 1000 lx, ideal,
    paper-target, default."""

    range_m: list[RangeM] | None = Field(
        None, min_length=1, max_length=64, description="target distance (m)"
    )
    attitude_deg: list[AttitudeDeg] | None = Field(
        None,
        min_length=1,
        max_length=64,
        description="attitude spread: pitch, yaw, roll each within +- this (deg)",
    )
    offset_fraction: list[OffsetFraction] | None = Field(
        None,
        min_length=1,
        max_length=64,
        description="target centre up to this fraction of the half field of view off axis",
    )
    ambient_lux: list[AmbientLux] | None = Field(None, min_length=1, max_length=64)
    physics: list[PhysicsFamily] | None = Field(
        None, min_length=1, description="domain-randomisation families (docs/simulator.md)"
    )
    catalog: list[str] | None = Field(None, min_length=1, max_length=16)
    preset: list[Literal["default", "paper"]] | None = Field(None, min_length=1)


class StudyCreate(StrictBody):
    """A study spec (``tofpose study --example`` prints one)."""

    name: str = Field("study", min_length=1, max_length=200, pattern=r"^[^\x00-\x1f]+$")
    seed: JsonInt = Field(0, ge=0, le=2**63 - 1)
    frames_per_cell: JsonInt = Field(100, ge=1, le=1_000_000)
    chunk_frames: JsonInt | None = Field(None, ge=1, le=100_000)
    grid: StudyGrid


class StudyPublic(BaseModel):
    id: int
    name: str
    status: Literal["created", "queued", "running", "complete", "incomplete", "failed"]
    cells: int
    frames_planned: int
    frames_done: int
    chunks: int
    chunks_done: int
    eta_s: float | None = Field(None, description="seconds to go at the rate so far")
    error: str | None = None
    started: str | None = None
    finished: str | None = None
    cluster: str | None = Field(None, description="the Dask cluster it ran on")
    reports: list[Literal["html", "pdf", "json"]] = Field(
        description="report files available at /api/studies/{id}/report.{html,pdf,json}"
    )


class ReprocessCreate(StrictBody):
    """Re-process a campaign's recording with another camera calibration."""

    camera: dict[str, Any] | None = Field(
        None,
        description="a camera JSON (tofpose.core.camera.CameraModel, with the "
        "range_correction "
        "and covariance_scale tofpose calibrate-range / calibrate-covariance add); omitted: "
        "the recording's own camera",
    )
    tracking: bool = Field(False, description="the pipeline's tracking mode")
    filter: bool = Field(False, description="add the relative-state filter's columns")


class ReprocessComparison(BaseModel):
    """The new calibration (B) against the recording's own camera (A), over the frames
    where both gave a pose (tofpose.batch.compare)."""

    frames: int
    ok_a: int
    ok_b: int
    gained: int
    lost: int
    attitude_diff_deg: dict[str, float | None]
    position_diff_mm: dict[str, float | None]
    mean_shift: dict[str, float | None]


class ReprocessPublic(BaseModel):
    id: int
    campaign_id: int
    camera: Literal["given", "recording"] = Field(
        description="the camera the run used: the request's or the recording's own"
    )
    tracking: bool
    filter: bool
    status: Literal["queued", "running", "complete", "failed", "cancelled"]
    created: str
    started: str | None = None
    finished: str | None = None
    error: str | None = None
    frames: int | None = None
    summary: ReprocessComparison | None = None
    files: list[
        Literal["poses.csv", "baseline.csv", "compare.csv", "compare.json", "compare.png"]
    ] = Field(description="downloadable at /api/reprocessings/{id}/files/{name}")
