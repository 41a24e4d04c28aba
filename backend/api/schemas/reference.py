"""The live reference (GET, PUT /api/reference)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from backend.api.schemas.common import RowId, StrictBody


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
