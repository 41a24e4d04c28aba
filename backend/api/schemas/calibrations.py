"""Bench calibrations (/api/calibrations)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field

from backend.api.schemas.common import JsonInt, StrictBody


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
