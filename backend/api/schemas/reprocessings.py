"""Re-processing of a campaign's recording (/api/reprocessings)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody


class ReprocessCreate(StrictBody):
    """Re-process a campaign's recording with another camera calibration."""

    camera: dict[str, Any] | None = Field(
        default=None,
        description="a camera JSON (tofpose.core.camera.CameraModel, with the "
        "range_correction "
        "and covariance_scale tofpose calibrate-range / calibrate-covariance add); omitted: "
        "the recording's own camera",
    )
    tracking: bool = Field(default=False, description="the pipeline's tracking mode")
    filter: bool = Field(default=False, description="add the relative-state filter's columns")


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
    dashboard_url: str | None = Field(
        default=None, description="the Dask dashboard while the job runs on a cluster"
    )
    frames_done: int | None = Field(
        default=None, description="frames output so far over both passes, while it runs"
    )
    frames_planned: int | None = Field(
        default=None, description="frames of both passes (twice the recording's), while it runs"
    )
    warnings: list[str] = Field(
        default_factory=list, description="what slows its cluster down (more workers than cores)"
    )
