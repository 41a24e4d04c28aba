"""Recordings on demand (/api/recordings)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody
from backend.services.recordings import MAX_DURATION_S, RecordingState, StopReason


class RecordingCreate(StrictBody):
    """A recording to start now."""

    name: str = Field(
        min_length=1,
        max_length=200,
        pattern=r"^[^\x00-\x1f]+$",
        description="what it is for (need not be unique)",
    )
    duration_s: float | None = Field(
        default=None,
        gt=0,
        le=MAX_DURATION_S,
        description="stop after this many seconds; null (the default): until stopped, "
        "or until the disk's free space falls below the floor",
    )


class RecordingPublic(BaseModel):
    """A recording: while it records, ``frames`` and ``size_bytes`` grow (the size is
    read about once a second); once stopped, ``stop_reason`` and ``stop_detail`` say why."""

    id: int
    name: str
    state: RecordingState
    started_utc: datetime
    stopped_utc: datetime | None
    duration_s: float | None = Field(description="the duration asked for; null: until stopped")
    elapsed_s: float = Field(description="from start to stop (or to now, while it records)")
    frames: int
    size_bytes: int
    dropped_frames: int = Field(
        description="frames the live stream delivered faster than the "
        "disk took them: not in the file"
    )
    stop_reason: StopReason | None
    stop_detail: str


class RecordingsPublic(BaseModel):
    """Every recording (newest first) and the disk they are written to."""

    recordings: list[RecordingPublic]
    free_mb: float = Field(description="free space on the data directory's disk, MB (10^6 B)")
    min_free_mb: float = Field(
        description="below this a recording is refused or stops (TOFPOSE_RECORDING_MIN_FREE_MB)"
    )
    used_mb: float = Field(description="what the recordings (HDF5 and MCAP files) take")
    max_active: int = Field(description="recordings that may run at once")
