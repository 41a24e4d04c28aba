"""The motion system: its state (GET /api/motion), manual moves, jogs and motion
profiles."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic.json_schema import SkipJsonSchema

from backend.api.schemas.common import DeviceStatePublic, JsonInt, StrictBody


class AxisPublic(BaseModel):
    name: str
    unit: str
    min_pos: float
    max_pos: float
    max_rate_per_s: float
    max_accel_per_s2: float | None = Field(
        default=None,
        description="acceleration limit; null when the motion system does not report "
        "one (then it runs no profiles on that axis)",
    )


ProfileKind = Literal["sine", "ramp"]


class ProfilePublic(BaseModel):
    """The motion profile running now (POST /api/motion/profile)."""

    axis: str
    kind: ProfileKind
    elapsed_s: float
    remaining_s: float
    duration_s: float = Field(description="the whole profile, fades and ramps included")


class MotionPublic(DeviceStatePublic):
    axes: list[AxisPublic] = []
    positions: dict[str, float] = Field(default_factory=dict, description="encoders, deg / mm")
    time_s: float | None = Field(
        default=None,
        description="when the encoders were read, s, on the clock of the camera's "
        "frames where the motion system shares it (the simulated lab), else the server's "
        "monotonic clock",
    )
    targets: dict[str, float] = Field(default_factory=dict)
    busy: bool = False
    settled: bool = True
    stopped: bool = False
    profile: ProfilePublic | None = Field(default=None, description="the profile running, if any")
    owner_campaign_id: int | None = Field(
        default=None,
        description="the campaign that owns the motion system while it runs (manual "
        "moves and jogs are refused with 409 then); null when it is free",
    )
    owner_campaign_name: str | None = None
    stop_latched: bool = Field(
        default=False,
        description="a person's STOP holds the motion system: every move, jog, profile and "
        "campaign is refused until POST /api/motion/release (or a campaign's resume)",
    )
    stop_latched_at: str | None = Field(
        default=None, description="when that STOP was pressed (UTC)"
    )


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
    cycles: JsonInt = Field(default=1, ge=1, le=1000, description="periods at full amplitude")


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
        default=None,
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
