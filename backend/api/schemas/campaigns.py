"""Campaigns (/api/campaigns): a campaign's request, its set-point generators, the
campaign as stored and run, its state machine and its measurements."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import AwareDatetime, BaseModel, BeforeValidator, ConfigDict, Field
from pydantic.json_schema import SkipJsonSchema

from backend.api.schemas.camera import CameraSettingsUpdate
from backend.api.schemas.common import StrictBody
from backend.api.schemas.motion import AxisBody, ProfileRequest
from backend.services.campaigns.campaign_states import CampaignCommand, CampaignState
from tofpose.lab.requirements import PAPER_REQUIREMENTS

MAX_SETPOINTS = 5000
MAX_FRAMES_PER_POINT = 100_000
MAX_FRAMES_PER_CAMPAIGN = 1_000_000
AngleDeg = Annotated[float, Field(ge=-360.0, le=360.0)]
RailMm = Annotated[float, Field(ge=0.0, le=100_000.0)]


class SetPointCamera(StrictBody):
    """Camera settings applied before a set-point's frames (docs/campaigns.md, "Camera
    settings and metadata"); a field left out keeps the camera's. Checked against the
    camera's limits when the campaign is created. An integration time turns the camera's
    auto exposure off for the set-point."""

    integration_time_us: float | None = Field(default=None, gt=0.0, le=1.0e6)
    modulation_frequency_mhz: float | None = Field(default=None, gt=0.0, le=1000.0)


Microseconds = Annotated[float, Field(gt=0.0, le=1.0e6)]
Megahertz = Annotated[float, Field(gt=0.0, le=1000.0)]
IntegrationTimes = Annotated[list[Microseconds], Field(min_length=1, max_length=50)]
ModulationFrequencies = Annotated[list[Megahertz], Field(min_length=1, max_length=10)]


class CameraSweep(StrictBody):
    """Every set-point measured at every combination of these lists (the set-point
    outermost, then integration time)."""

    model_config = ConfigDict(json_schema_extra={"minProperties": 1})

    integration_time_us: IntegrationTimes | None = None
    modulation_frequency_mhz: ModulationFrequencies | None = None


class SetPointModel(AxisBody):
    """Axis set-points of one campaign point; an axis left out stays where it is;
    ``camera``: the camera settings for its frames."""

    yaw_deg: AngleDeg | SkipJsonSchema[None] = None
    pitch_deg: AngleDeg | SkipJsonSchema[None] = None
    roll_deg: AngleDeg | SkipJsonSchema[None] = None
    rail_mm: RailMm | SkipJsonSchema[None] = None
    camera: SetPointCamera | SkipJsonSchema[None] = None

    def axes(self) -> dict[str, float]:
        return {
            k.rsplit("_", 1)[0]: v
            for k, v in self.model_dump(exclude={"camera"}).items()
            if v is not None
        }

    def camera_setting(self) -> dict[str, float]:
        """The fields of ``camera`` given ({} for none)."""
        return self.camera.model_dump(exclude_none=True) if self.camera else {}


class Requirements(StrictBody):
    """Accuracy requirements per axis (default: the paper's, §6.4,
    ``tofpose.lab.requirements.PAPER_REQUIREMENTS``): a set-point passes an
    axis when the largest |error| after singular-point removal is within it."""

    x_mm: float = Field(default=PAPER_REQUIREMENTS["x_mm"], gt=0, le=1e5)
    y_mm: float = Field(default=PAPER_REQUIREMENTS["y_mm"], gt=0, le=1e5)
    z_mm: float = Field(default=PAPER_REQUIREMENTS["z_mm"], gt=0, le=1e5)
    pitch_deg: float = Field(default=PAPER_REQUIREMENTS["pitch_deg"], gt=0, le=180)
    yaw_deg: float = Field(default=PAPER_REQUIREMENTS["yaw_deg"], gt=0, le=180)
    roll_deg: float = Field(default=PAPER_REQUIREMENTS["roll_deg"], gt=0, le=180)


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
    amplitude_deg: float = Field(default=8.0, gt=0, le=45)


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
    rest_s: float = Field(default=2.0, ge=0.5, le=600.0, description="rest before and after, s")
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
    catalog: str = Field(default="paper-target", min_length=1, max_length=128)
    frames_per_point: int = Field(default=30, ge=1, le=MAX_FRAMES_PER_POINT)
    settle_s: float = Field(default=1.0, ge=0.0, le=3600.0)
    lock_timeout_s: float = Field(default=5.0, gt=0.0, le=3600.0)
    setpoints: (
        Annotated[list[SetPointModel], Field(min_length=1, max_length=MAX_SETPOINTS)] | None
    ) = None
    generator: Generator | None = None
    requirements: Requirements = Field(default_factory=Requirements)
    camera: CameraSettingsUpdate | None = None
    camera_sweep: CameraSweep | None = Field(
        default=None,
        description="measure every set-point at each of these camera settings "
        "(not with a per-set-point 'camera')",
    )
    operator: str | None = Field(
        default=None, max_length=200, pattern=r"^[^\x00-\x1f]*$", description="who runs it"
    )
    target_name: str | None = Field(
        default=None, max_length=200, pattern=r"^[^\x00-\x1f]*$", description="the target measured"
    )
    camera_model: str | None = Field(
        default=None, max_length=200, description="when the camera's driver does not report it"
    )
    camera_serial: str | None = Field(
        default=None, max_length=200, description="when the camera's driver does not report it"
    )
    camera_firmware: str | None = Field(
        default=None, max_length=200, description="when the camera's driver does not report it"
    )
    record_raw: bool = Field(
        default=False,
        description="keep every measured frame pair in an HDF5 recording "
        "(GET /api/campaigns/{id}/recording.h5), so the campaign can be re-processed",
    )
    notes: str = Field(default="", max_length=4000)


def _iso_text(v: object) -> object:
    """A date-time in JSON is ISO 8601 text (not a number of seconds)."""
    if v is not None and not isinstance(v, str | datetime):
        raise ValueError("must be an ISO 8601 date-time with a time zone, as text")
    return v


class CampaignStart(StrictBody):
    """Start now (``at`` left out) or at a given time (ISO 8601 with a time zone).

    While another campaign owns the motion system, starting now is refused (409) unless
    ``queue`` is true: then this one runs when the other finishes."""

    at: Annotated[AwareDatetime, BeforeValidator(_iso_text)] | None = Field(
        default=None, strict=False
    )
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
    camera: dict[str, float] | None = Field(
        default=None, description="camera settings of the set-point in progress (null: as it is)"
    )


class SetPointPublic(BaseModel):
    index: int
    yaw_deg: float | None
    pitch_deg: float | None
    roll_deg: float | None
    rail_mm: float | None
    profile: dict | None = Field(
        default=None,
        description="a dynamic set-point's motion profile (axis, kind, its fields, "
        "rest_s), null at a static one",
    )
    camera: dict[str, float] | None = Field(
        default=None, description="camera settings for its frames; null: the camera as it is"
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
    camera_sweep: dict | None = None
    operator: str = ""
    target_name: str = ""
    camera_model: str = ""
    camera_serial: str = ""
    camera_firmware: str = ""
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
    truth: dict[str, float] | None = Field(
        description="the pose the simulator rendered (null on real hardware)"
    )
    reference: dict[str, float] | None = Field(
        default=None, description="the lab's reference: encoders + nominal geometry"
    )
    lab_truth: dict[str, float] | None = Field(
        default=None,
        deprecated=True,
        description="deprecated, removed in the next release: `reference` under its older name",
    )
    encoders: dict[str, float] | None
    integration_time_us: float | None = Field(
        default=None, description="the exposure the camera reports for the frame"
    )
    pixel_fit: str | None = Field(
        default=None,
        description="'ok' when the pose and sigmas are the pixel-level fit's (the server's "
        "TOFPOSE_PIXEL_FIT), else why the centroid pose stands; null when it did not run",
    )
    in_motion: bool | None = Field(
        default=None,
        description="taken while the set-point's motion profile ran (null at a static set-point)",
    )


class MeasurementPage(BaseModel):
    total: int
    offset: int
    items: list[MeasurementPublic]
