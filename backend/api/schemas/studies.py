"""Accuracy studies (``tofpose.study``; docs/scaleout.md; /api/studies)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, Field

from backend.api.schemas.campaigns import Requirements
from backend.api.schemas.common import JsonInt, StrictBody
from tofpose.study.spec import DEFAULT_PERCENTILE, MIN_PERCENTILE

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
        default=None, min_length=1, max_length=64, description="target distance (m)"
    )
    attitude_deg: list[AttitudeDeg] | None = Field(
        default=None,
        min_length=1,
        max_length=64,
        description="attitude spread: pitch, yaw, roll each within +- this (deg)",
    )
    offset_fraction: list[OffsetFraction] | None = Field(
        default=None,
        min_length=1,
        max_length=64,
        description="target centre up to this fraction of the half field of view off axis",
    )
    ambient_lux: list[AmbientLux] | None = Field(default=None, min_length=1, max_length=64)
    physics: list[PhysicsFamily] | None = Field(
        default=None, min_length=1, description="domain-randomisation families (docs/simulator.md)"
    )
    catalog: list[str] | None = Field(default=None, min_length=1, max_length=16)
    preset: list[Literal["default", "paper"]] | None = Field(default=None, min_length=1)


class StudyRequirements(Requirements):
    """The accuracy a cell is judged against (``tofpose.study.spec``): per axis the
    campaign's requirement (same fields, same defaults), and the share of a cell's frames
    that must have a pose within it."""

    percentile: float = Field(
        default=DEFAULT_PERCENTILE,
        ge=MIN_PERCENTILE,
        le=100.0,
        description="share of a cell's frames (%) that must be within each requirement",
    )


class StudyCreate(StrictBody):
    """A study spec (``tofpose study --example`` prints one)."""

    name: str = Field(default="study", min_length=1, max_length=200, pattern=r"^[^\x00-\x1f]+$")
    seed: JsonInt = Field(default=0, ge=0, le=2**63 - 1)
    frames_per_cell: JsonInt = Field(default=100, ge=1, le=1_000_000)
    chunk_frames: JsonInt | None = Field(default=None, ge=1, le=100_000)
    grid: StudyGrid
    requirements: StudyRequirements = Field(default_factory=StudyRequirements)


class StudyPublic(BaseModel):
    id: int
    name: str
    status: Literal["created", "queued", "running", "complete", "incomplete", "failed"]
    cells: int
    frames_planned: int
    frames_done: int
    chunks: int
    chunks_done: int
    eta_s: float | None = Field(default=None, description="seconds to go at the rate so far")
    error: str | None = None
    started: str | None = None
    finished: str | None = None
    cluster: str | None = Field(default=None, description="the Dask cluster it ran on")
    reports: list[Literal["html", "pdf", "json"]] = Field(
        description="report files available at /api/studies/{id}/report.{html,pdf,json}"
    )
    dashboard_url: str | None = Field(
        default=None, description="the Dask dashboard of the cluster running it, while it runs"
    )
    warnings: list[str] = Field(
        default_factory=list, description="what slows its cluster down (more workers than cores)"
    )
