"""Recordings on demand (docs/server.md, "Recordings on demand"): start a named recording
of the live stream, stop it, list and read them, download one as HDF5 or MCAP, delete it.

What a recording holds, when it stops and how the disk is guarded:
backend/services/recordings.py.
"""

from __future__ import annotations

import pathlib
import re
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, status
from fastapi.responses import FileResponse

from backend.api.contract import ErrorPublic, errors
from backend.api.deps import AdminAuth, McapProfileQuery, ReadAuth, StateDep, WriteAuth
from backend.api.schemas.recordings import RecordingCreate, RecordingPublic, RecordingsPublic
from backend.services.campaigns.mcap_files import recording_mcap
from backend.services.recordings import (
    MB,
    RecordingInfo,
    RecordingService,
)
from backend.state import AppState
from tofpose.io.interop import DEFAULT_MCAP_PROFILE, MCAP_SUFFIXES

router = APIRouter(prefix="/api/recordings", tags=["recordings"])
RecordingIdParam = Annotated[int, Path(ge=1, le=2**31 - 1)]
NO_SPACE_TEXT = (
    "Less free space on the data directory's disk than "
    "TOFPOSE_RECORDING_MIN_FREE_MB: nothing was started"
)
NO_SPACE: dict[int | str, dict[str, Any]] = {
    507: {"model": ErrorPublic, "description": NO_SPACE_TEXT}
}
EXPORT_SPACE: dict[int | str, dict[str, Any]] = {
    507: {
        "model": ErrorPublic,
        "description": "too little free disk space to export: twice "
        "the recording plus TOFPOSE_RECORDING_MIN_FREE_MB are needed",
    }
}
BUSY: dict[int | str, dict[str, Any]] = {
    503: {
        "model": ErrorPublic,
        "description": "busy with other reports and exports: try again (Retry-After)",
    }
}


def _service(state: AppState) -> RecordingService:
    if state.recordings is None:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "recordings are not running")
    return state.recordings


def _public(info: RecordingInfo) -> RecordingPublic:
    return RecordingPublic(
        id=info.id,
        name=info.name,
        state=info.state,
        started_utc=info.started_utc,
        stopped_utc=info.stopped_utc,
        duration_s=info.duration_s,
        elapsed_s=info.elapsed_s,
        frames=info.frames,
        size_bytes=info.size_bytes,
        dropped_frames=info.dropped_frames,
        stop_reason=info.stop_reason,
        stop_detail=info.stop_detail,
    )


def _download_name(info: RecordingInfo, suffix: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9._-]+", "-", info.name).strip("-.")[:60] or "recording"
    return f"{slug}-{info.id}.{suffix}"


def _file(service: RecordingService, recording_id: int) -> tuple[RecordingInfo, pathlib.Path]:
    """(entry, HDF5 path) of a stopped recording: 404 unknown, 409 while it records."""
    return service.get(recording_id), service.file(recording_id)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteAuth],
    responses={**errors(409), **NO_SPACE},
)
def start_recording(body: RecordingCreate, state: StateDep) -> RecordingPublic:
    """Start recording the live stream now: every frame with its pose and covariance, the
    relative state, the references, the turntable's encoders and targets and a UTC
    stamp, into one HDF5 recording (docs/architecture.md §7 plus the groups listed in
    docs/server.md). 507 below the free-space floor; 409 while the most recordings that
    may run at once (``max_active`` of the list) already run."""
    return _public(_service(state).start(body.name, body.duration_s))


@router.get("", dependencies=[ReadAuth])
def list_recordings(state: StateDep) -> RecordingsPublic:
    """Every recording, newest first, with the free space left on the disk they go to."""
    service = _service(state)
    return RecordingsPublic(
        recordings=[_public(i) for i in service.list()],
        free_mb=service.free_mb(),
        min_free_mb=service.min_free_mb,
        used_mb=service.used_bytes / MB,
        max_active=service.max_active,
    )


@router.get("/{recording_id}", dependencies=[ReadAuth], responses=errors(404))
def get_recording(recording_id: RecordingIdParam, state: StateDep) -> RecordingPublic:
    """One recording: while it records, its frames, size and time so far."""
    return _public(_service(state).get(recording_id))


@router.post("/{recording_id}/stop", dependencies=[WriteAuth], responses=errors(404))
def stop_recording(recording_id: RecordingIdParam, state: StateDep) -> RecordingPublic:
    """Stop a recording: the frames the live stream delivered until now are written, the
    file is closed, and the answer is its final entry. A stopped recording is answered as
    it is (stopping twice changes nothing)."""
    return _public(_service(state).stop(recording_id))


@router.get(
    "/{recording_id}/recording.h5",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={
        200: {"content": {"application/x-hdf5": {}}, "description": "the recording"},
        **errors(404, 409),
    },
)
def get_recording_h5(recording_id: RecordingIdParam, state: StateDep):
    """The recording (HDF5): readable with ``tofpose.io.recording.open_recording`` and every
    ``tofpose`` command that takes a recording. 409 while it records."""
    info, path = _file(_service(state), recording_id)
    return FileResponse(path, media_type="application/x-hdf5", filename=_download_name(info, "h5"))


@router.get(
    "/{recording_id}/recording.mcap",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={
        200: {"content": {"application/x-mcap": {}}, "description": "the recording"},
        **errors(404, 409),
        **BUSY,
        **EXPORT_SPACE,
    },
)
async def get_recording_mcap(
    recording_id: RecordingIdParam,
    state: StateDep,
    profile: McapProfileQuery = DEFAULT_MCAP_PROFILE,
):
    """The recording as MCAP for Foxglove and Rerun, or with ``profile=ros2`` as ROS 2
    messages (docs/interop.md), made as a campaign's is: frames, references and an
    estimate of each frame by the pipeline re-run over the recording. Made on the first
    request and kept, on the server's export workers (503 with Retry-After while they
    and their queue are full). 409 while it records."""
    info, path = _file(_service(state), recording_id)
    out = await state.heavy_work.run(
        lambda: recording_mcap(path, state.settings.recording_min_free_mb, profile),
        f"the {profile} MCAP of recording {recording_id}",
    )
    name = _download_name(info, MCAP_SUFFIXES[profile].lstrip("."))
    return FileResponse(out, media_type="application/x-mcap", filename=name)


@router.delete(
    "/{recording_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    dependencies=[AdminAuth],
    responses=errors(404, 409),
)
def delete_recording(recording_id: RecordingIdParam, state: StateDep) -> None:
    """Delete a recording's files (HDF5 and its MCAP) and entry; admin scope. 409 while it
    records (stop it first)."""
    _service(state).delete(recording_id)
