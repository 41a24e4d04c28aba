"""Campaigns: create, list, read, start / pause / resume / cancel, measurements, reports.

States and what each command does: docs/campaigns.md.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Query, Response, status
from fastapi.responses import FileResponse

from backend.api.contract import errors
from backend.api.deps import (
    Location,
    McapProfileQuery,
    ReadAuth,
    SessionDep,
    StateDep,
    WriteAuth,
    finished_recording,
    unprocessable,
    unprocessable_at,
)
from backend.api.presenters import campaign_public, campaign_states_public, measurement_public
from backend.api.schemas.campaigns import (
    MAX_FRAMES_PER_CAMPAIGN,
    MAX_SETPOINTS,
    CampaignCreate,
    CampaignPublic,
    CampaignStart,
    CampaignStatesPublic,
    MeasurementPage,
)
from backend.services.calibrations import get_calibration
from backend.services.campaigns.camera_plan import (
    camera_identity,
    camera_limits,
    plan_cameras,
    raw_recording_problems,
)
from backend.services.campaigns.campaign_repository import CampaignView
from backend.services.campaigns.campaign_requests import (
    Planning,
    dynamic_spec,
    expand,
    plan_problems,
    profile_plan_problems,
)
from backend.services.campaigns.mcap_files import recording_mcap
from backend.services.reports.reports import ReportError, build, to_csv, to_html, to_json, to_pdf
from backend.services.store import find_catalog
from backend.state import AppState
from tofpose.io.interop import DEFAULT_MCAP_PROFILE, MCAP_SUFFIXES

router = APIRouter(prefix="/api/campaigns", tags=["campaigns"])
IdParam = Annotated[int, Path(ge=1, le=2**31 - 1)]
EXPORT_SPACE: dict[int | str, dict[str, Any]] = {
    507: {
        **errors(503)[503],
        "description": "too little free disk space to export: "
        "twice the recording plus TOFPOSE_RECORDING_MIN_FREE_MB are needed",
    }
}
BUSY: dict[int | str, dict[str, Any]] = {
    503: {
        **errors(503)[503],
        "description": "busy with other reports and exports: try again (Retry-After)",
    }
}


def _planning(state: AppState) -> Planning:
    return Planning.read(state.motion, state.devices.camera.get_settings().frame_rate_hz)


def _public(
    state: AppState,
    campaign: CampaignView,
    planning: Planning | None = None,
    *,
    with_setpoints: bool = False,
) -> CampaignPublic:
    estimate_s = (planning or _planning(state)).estimate_s(campaign)
    progress = state.campaigns.progress(campaign.id)
    return campaign_public(campaign, progress, estimate_s, with_setpoints=with_setpoints)


def _setpoints(body: CampaignCreate) -> list[dict[str, float]]:
    """The set-point list of a request: explicit, or from its generator."""
    if body.generator is None:
        return [sp.axes() for sp in body.setpoints or []]
    try:
        return expand(body.generator.model_dump())
    except ValueError as exc:
        raise unprocessable(["body", "generator"], [str(exc)]) from exc


@router.post(
    "", status_code=status.HTTP_201_CREATED, dependencies=[WriteAuth], responses=errors(409)
)
def create_campaign(body: CampaignCreate, state: StateDep, session: SessionDep) -> CampaignPublic:
    """Store a draft campaign (start it with ``POST /api/campaigns/{id}/start``).

    422 names every problem: no set-points, both or neither of ``setpoints`` and
    ``generator``, set-points outside the soft limits, too many set-points or frames, an
    unknown catalog, camera settings outside the camera's limits (the field and the allowed
    range named), a raw recording over more than one modulation frequency (one camera model
    per recording), a camera serial or firmware the connected camera contradicts. 409 if
    the name is taken. Nothing is stored on an error.
    """
    if body.setpoints is not None and body.generator is not None:
        raise unprocessable(["body"], ["give either 'setpoints' or 'generator', not both"])
    camera = state.devices.camera
    setpoints, cameras, camera_problems = plan_cameras(
        _setpoints(body),
        [sp.camera_setting() for sp in body.setpoints] if body.setpoints else None,
        body.camera_sweep.model_dump(exclude_none=True) if body.camera_sweep else None,
        body.camera.model_dump(exclude_none=True) if body.camera else None,
        camera_limits(camera),
        camera.name,
    )
    describe = getattr(camera, "describe", None)
    identity, identity_problems = camera_identity(
        describe() if callable(describe) else {},
        body.model_dump(include={"camera_model", "camera_serial", "camera_firmware"}),
    )
    motion = state.motion
    problems = plan_problems(
        setpoints,
        motion.axes if motion.present else None,
        frames_per_point=body.frames_per_point,
        max_setpoints=MAX_SETPOINTS,
        max_frames=MAX_FRAMES_PER_CAMPAIGN,
    )
    if find_catalog(session, body.catalog) is None:
        problems.append(f"no catalog named {body.catalog!r} (GET /api/catalogs lists them)")
    generator = body.generator.model_dump() if body.generator else None
    spec = dynamic_spec(generator, motion)
    located = profile_plan_problems(setpoints, spec, motion) if spec is not None else []
    located += camera_problems + identity_problems
    if not camera_problems:
        located += raw_recording_problems(
            cameras,
            body.camera.model_dump(exclude_none=True) if body.camera else None,
            body.record_raw,
        )
    at_body: list[tuple[Location, str]] = [(["body"], p) for p in problems]
    if at_body or located:
        raise unprocessable_at([*at_body, *located])
    campaign = state.campaigns.repository.create(
        name=body.name,
        catalog_name=body.catalog,
        setpoints=setpoints,
        frames_per_point=body.frames_per_point,
        settle_s=body.settle_s,
        lock_timeout_s=body.lock_timeout_s,
        requirements=body.requirements.model_dump(),
        generator=generator,
        camera=body.camera.model_dump(exclude_none=True) if body.camera else None,
        notes=body.notes,
        record_raw=body.record_raw,
        profiles=[spec] * len(setpoints) if spec is not None else None,
        cameras=cameras,
        camera_sweep=body.camera_sweep.model_dump(exclude_none=True) if body.camera_sweep else None,
        metadata={
            "operator": body.operator or "",
            "target_name": body.target_name or "",
            **identity,
        },
    )
    return _public(state, campaign, with_setpoints=True)


@router.get("", dependencies=[ReadAuth])
def list_campaigns(state: StateDep) -> list[CampaignPublic]:
    """Every campaign, newest first, without its set-point list."""
    planning = _planning(state)
    return [_public(state, c, planning) for c in state.campaigns.repository.list()]


@router.get("/states", dependencies=[ReadAuth])
def get_campaign_states() -> CampaignStatesPublic:
    """The campaign state machine: every state, the finished ones, and each command
    (``POST /api/campaigns/{id}/{command}``) with the states it is accepted in and the
    state it leads to; any other command answers 409 (docs/campaigns.md, "States")."""
    return campaign_states_public()


@router.get("/{campaign_id}", dependencies=[ReadAuth], responses=errors(404))
def get_campaign(campaign_id: IdParam, state: StateDep) -> CampaignPublic:
    """One campaign with its set-points and, while it runs, its progress."""
    return _public(state, state.campaigns.repository.get(campaign_id), with_setpoints=True)


def _command(state: AppState, campaign_id: int, fn) -> CampaignPublic:
    state.campaigns.repository.get(campaign_id)  # 404 before any command
    fn()
    return _public(state, state.campaigns.repository.get(campaign_id), with_setpoints=True)


@router.post("/{campaign_id}/start", dependencies=[WriteAuth], responses=errors(404, 409))
def start_campaign(
    campaign_id: IdParam, state: StateDep, body: CampaignStart | None = None
) -> CampaignPublic:
    """Queue the campaign: it runs as soon as the motion system is free, or at ``at``.
    409 while a STOP is latched (POST /api/motion/release first)."""
    body = body or CampaignStart()
    return _command(
        state,
        campaign_id,
        lambda: state.campaigns.start_campaign(campaign_id, body.at, queue=body.queue),
    )


@router.post("/{campaign_id}/pause", dependencies=[WriteAuth], responses=errors(404, 409))
def pause_campaign(campaign_id: IdParam, state: StateDep) -> CampaignPublic:
    """Pause a running (or queued) campaign; the set-point in progress is measured again
    on resume."""
    return _command(state, campaign_id, lambda: state.campaigns.pause(campaign_id))


@router.post("/{campaign_id}/resume", dependencies=[WriteAuth], responses=errors(404, 409))
def resume_campaign(campaign_id: IdParam, state: StateDep) -> CampaignPublic:
    """Queue a paused or interrupted campaign again; it continues at its first set-point
    not done. A resume is a person deciding that the table may move: it releases a
    latched STOP too."""
    return _command(state, campaign_id, lambda: state.campaigns.resume(campaign_id))


@router.post("/{campaign_id}/cancel", dependencies=[WriteAuth], responses=errors(404, 409))
def cancel_campaign(campaign_id: IdParam, state: StateDep) -> CampaignPublic:
    """Cancel for good (what was measured stays stored and reportable)."""
    return _command(state, campaign_id, lambda: state.campaigns.cancel(campaign_id))


@router.get("/{campaign_id}/measurements", dependencies=[ReadAuth], responses=errors(404))
def list_measurements(
    campaign_id: IdParam,
    state: StateDep,
    offset: Annotated[int, Query(ge=0, le=10_000_000)] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> MeasurementPage:
    """Stored frames of the campaign, in set-point then frame order, a page at a time."""
    total, rows = state.campaigns.repository.measurements(campaign_id, offset, limit)
    return MeasurementPage(
        total=total, offset=offset, items=[measurement_public(m, i) for m, i in rows]
    )


class ReportFormat(StrEnum):
    html = "html"
    pdf = "pdf"
    csv = "csv"
    json = "json"


class Reference(StrEnum):
    """What a report's errors are measured against: ``lab`` the lab's reference (encoders
    + nominal geometry), ``truth`` the pose the simulator rendered; ``exact`` is the older
    name of ``truth`` (docs/interop.md, "Names: truth and reference")."""

    lab = "lab"
    truth = "truth"
    exact = "exact"


MEDIA_TYPES = {
    "html": "text/html; charset=utf-8",
    "pdf": "application/pdf",
    "csv": "text/csv; charset=utf-8",
    "json": "application/json",
}


@router.get(
    "/{campaign_id}/report.{fmt}",
    dependencies=[ReadAuth],
    response_class=Response,
    responses={
        200: {"content": {m: {} for m in MEDIA_TYPES.values()}, "description": "the report"},
        **errors(404),
        **BUSY,
    },
)
async def get_campaign_report(
    campaign_id: IdParam,
    fmt: ReportFormat,
    state: StateDep,
    reference: Annotated[
        Reference,
        Query(
            description="lab: the lab's reference (encoders + nominal geometry); truth: the "
            "pose the simulator rendered (simulator only); exact: older name of truth"
        ),
    ] = Reference.lab,
    calibration: Annotated[
        int | None,
        Query(ge=1, le=2**31 - 1, description="reference = encoders + this calibration"),
    ] = None,
    inline: Annotated[
        bool, Query(description="show in the browser instead of downloading (the dashboard)")
    ] = False,
) -> Response:
    """The accuracy report: HTML (self-contained), PDF, CSV (one row per frame) or JSON
    (every statistic). Statistics against the lab's reference by default. Rendered on the
    server's report workers: 503 with Retry-After while they and their queue are full."""

    def render() -> str | bytes:
        state.campaigns.repository.get(campaign_id)  # 404 for no such campaign
        with state.sessions() as session:
            cal = None
            if calibration is not None and (cal := get_calibration(session, calibration)) is None:
                raise HTTPException(404, f"no calibration with id {calibration}")
            try:
                report, rows = build(session, campaign_id, reference.value, cal)
            except ReportError as exc:
                raise unprocessable(["query", "reference"], [str(exc)]) from exc
        if fmt is ReportFormat.csv:
            return to_csv(rows)
        if fmt is ReportFormat.json:
            return to_json(report)
        if fmt is ReportFormat.html:
            return to_html(report, rows)
        return to_pdf(report, rows)

    # on the report and export workers: 503 with Retry-After when they and their queue are full
    body = await state.heavy_work.run(render, f"the {fmt.value} report of campaign {campaign_id}")
    filename = f"campaign-{campaign_id}-report.{fmt.value}"
    return Response(
        body,
        media_type=MEDIA_TYPES[fmt.value],
        headers={
            "Content-Disposition": f'{"inline" if inline else "attachment"}; filename="{filename}"'
        },
    )


@router.get(
    "/{campaign_id}/recording.h5",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={
        200: {"content": {"application/x-hdf5": {}}, "description": "the recording"},
        **errors(404, 409),
    },
)
def get_campaign_recording(campaign_id: IdParam, state: StateDep):
    """The campaign's raw frames (HDF5, docs/architecture.md §7): exactly the stored
    measurements, in order (``recording_index`` of each). Only with ``record_raw``."""
    path = finished_recording(state, campaign_id)
    return FileResponse(
        path, media_type="application/x-hdf5", filename=f"campaign-{campaign_id}.h5"
    )


@router.get(
    "/{campaign_id}/recording.mcap",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={
        200: {"content": {"application/x-mcap": {}}, "description": "the recording"},
        **errors(404, 409),
        **BUSY,
        **EXPORT_SPACE,
    },
)
async def get_campaign_recording_mcap(
    campaign_id: IdParam,
    state: StateDep,
    profile: McapProfileQuery = DEFAULT_MCAP_PROFILE,
):
    """The campaign's raw recording as MCAP for Foxglove and Rerun, or with
    ``profile=ros2`` as ROS 2 messages (docs/interop.md): the frames, the references and
    an estimate of each frame by the pipeline re-run over the recording (its camera and
    catalog, default settings, tracking off; not the stored measurement rows). Made on
    the first request (a long recording takes a while) and kept, on the server's export
    workers (503 with Retry-After while they and their queue are full). Only with
    ``record_raw``."""

    def export():  # the recording's lookup reads the database: off the event loop too
        return recording_mcap(
            finished_recording(state, campaign_id),
            state.settings.recording_min_free_mb,
            profile,
        )

    out = await state.heavy_work.run(export, f"the {profile} MCAP of campaign {campaign_id}")
    return FileResponse(
        out,
        media_type="application/x-mcap",
        filename=f"campaign-{campaign_id}{MCAP_SUFFIXES[profile]}",
    )
