"""Re-processing of a stored campaign's recording with another camera calibration, on
Dask (docs/scaleout.md): submit, list, follow, cancel, download the poses and the
comparison with the recording's own camera."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Path, Query, status
from fastapi.responses import FileResponse

from backend.api.contract import errors
from backend.api.deps import (
    ReadAuth,
    StateDep,
    WriteAuth,
    finished_recording,
)
from backend.api.schemas.reprocessings import ReprocessCreate, ReprocessPublic
from backend.services.jobs.reprocessing import (
    FILES,
)

router = APIRouter(prefix="/api", tags=["reprocessing"])

IdParam = Annotated[int, Path(ge=1, le=2**31 - 1)]
FileName = Literal["poses.csv", "baseline.csv", "compare.csv", "compare.json", "compare.png"]


@router.post(
    "/campaigns/{campaign_id}/reprocess",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteAuth],
    responses=errors(404, 409),
)
def create_reprocessing(
    campaign_id: IdParam, body: ReprocessCreate, state: StateDep
) -> ReprocessPublic:
    """Queue a re-processing of the campaign's recording with ``camera`` (and, as the
    baseline, with the camera it was recorded with). 404 without the campaign, 409 when it
    has no recording (it ran with ``record_raw`` off) or is writing it, 422 naming
    ``camera`` when it is not a camera JSON or does not fit the recording's frames;
    nothing is stored then."""
    path = finished_recording(state, campaign_id, missing_status=409)
    job = state.reprocessings.submit(
        campaign_id, path, body.camera, tracking=body.tracking, filter_state=body.filter
    )
    return ReprocessPublic(**job)


@router.get("/reprocessings", dependencies=[ReadAuth])
def list_reprocessings(
    state: StateDep,
    campaign_id: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None,
) -> list[ReprocessPublic]:
    """Every re-processing (of ``campaign_id`` when given), newest first."""
    return [ReprocessPublic(**j) for j in state.reprocessings.list(campaign_id)]


@router.get("/reprocessings/{job_id}", dependencies=[ReadAuth], responses=errors(404))
def get_reprocessing(job_id: IdParam, state: StateDep) -> ReprocessPublic:
    """A re-processing's status and, once complete, its comparison."""
    return ReprocessPublic(**state.reprocessings.status(job_id))


@router.post("/reprocessings/{job_id}/cancel", dependencies=[WriteAuth], responses=errors(404))
def cancel_reprocessing(job_id: IdParam, state: StateDep) -> ReprocessPublic:
    """Cancel a queued or running re-processing; a finished one is returned as it is."""
    return ReprocessPublic(**state.reprocessings.cancel(job_id))


@router.get(
    "/reprocessings/{job_id}/files/{name}",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={**errors(404, 409), 200: {"content": {m: {} for _, m in FILES.values()}}},
)
def reprocessing_file(job_id: IdParam, name: FileName, state: StateDep):
    """A result file: ``poses.csv`` (the new calibration's, as ``tofpose estimate`` writes
    it), ``baseline.csv`` (the recording's own camera), ``compare.csv|json|png``. 409 until
    the re-processing is complete."""
    path = state.reprocessings.file_path(job_id, name)
    if path is None:
        raise HTTPException(409, f"re-processing {job_id} has no {name} yet (it is not complete)")
    return FileResponse(path, media_type=FILES[name][1], filename=f"reprocessing-{job_id}-{name}")
