"""Campaigns: create, list, read, start / pause / resume / cancel, measurements, reports.

States and what each command does: docs/campaigns.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Response, status
from fastapi.responses import FileResponse
from sqlalchemy import func, select

from backend.api.contract import errors
from backend.api.deps import (
    ReadAuth,
    SessionDep,
    StateDep,
    WriteAuth,
    finished_recording,
    unprocessable,
    unprocessable_at,
)
from backend.api.presenters import campaign_public, measurement_public
from backend.api.schemas import (
    MAX_FRAMES_PER_CAMPAIGN,
    MAX_SETPOINTS,
    CampaignCreate,
    CampaignPublic,
    CampaignStart,
    MeasurementPage,
)
from backend.db.models import CalibrationRow, CampaignRow, MeasurementRow, SetPointRow
from backend.drivers.base import profile_axis_problem, profile_problems
from backend.services import campaign_plan
from backend.services.campaigns import (
    CampaignConflictError,
    CampaignNotFoundError,
    plan_problems,
    setpoint_axes,
)
from backend.services.campaigns import create_campaign as store_campaign
from backend.services.mcap_files import recording_mcap
from backend.services.reports import ReportError, build, to_csv, to_html, to_json, to_pdf
from backend.services.store import NameTakenError, find_catalog
from backend.state import AppState
from tofpose.motion_profile import profile_from_spec

router = APIRouter(prefix="/api/campaigns", tags=["campaigns"])
IdParam = Annotated[int, Path(ge=1, le=2**31 - 1)]


def expand(body: CampaignCreate) -> list[dict[str, float]]:
    """The set-point list of a request: explicit, or from its generator."""
    if body.generator is None:
        return [sp.axes() for sp in body.setpoints or []]
    g = body.generator.model_dump()
    kind = g.pop("kind")
    if kind == "grid":
        return campaign_plan.grid(**g)
    if kind == "range_sweep":
        return campaign_plan.range_sweep(**g)
    if kind == "stability":
        return campaign_plan.stability(**g)
    if kind == "attitude_steps":
        return campaign_plan.attitude_steps(**g)
    if kind == "profile":
        return campaign_plan.profile_starts(
            axis=g["profile"]["axis"], **{a: g[a] for a in AXIS_FIELDS}
        )
    return campaign_plan.calibration(**g)


AXIS_FIELDS = ("yaw_deg", "pitch_deg", "roll_deg", "rail_mm")


def dynamic_spec(body: CampaignCreate) -> dict | None:
    """The motion profile (with ``rest_s``) every set-point of a dynamic campaign runs,
    as stored on its set-points; None for a static campaign."""
    g = body.generator
    if g is None or g.kind != "profile":
        return None
    return {**g.profile.model_dump(exclude_none=True), "rest_s": g.rest_s}


def profile_plan_problems(
    setpoints: list[dict[str, float]], spec: dict, motion
) -> list[tuple[list, str]]:
    """(loc, message) for every reason the profile cannot run from a start point: no
    profile mode, the axis, its soft/rate/acceleration limits (by the request field)."""
    if motion is None:
        return []  # plan_problems names the missing motion system
    if not callable(getattr(motion, "run_profile", None)):
        return [(["body", "generator", "profile"],
                 f"the {motion.name!r} motion system cannot run motion profiles")]  # fmt: skip
    if (why := getattr(motion, "profile_unavailable", None)) is not None:
        return [(["body", "generator", "profile"], why)]
    axis = spec["axis"]
    if (problem := profile_axis_problem(motion.axes, axis)) is not None:
        return [(["body", "generator", "profile", problem.field], problem.message)]
    profile = profile_from_spec(spec, motion.axes[axis].max_accel)
    out = []
    for i, sp in enumerate(setpoints):
        for p in profile_problems(motion.axes, axis, profile.started_at(sp[axis])):
            out.append((["body", "generator", "profile", p.field], f"start point {i}: {p.message}"))
        if len(out) > 20:
            break
    return out


@dataclass(frozen=True)
class Planning:
    """What a duration estimate needs from the devices, read once per request (a real
    motion controller answers each status query over the wire)."""

    start: dict[str, float]
    rates: dict[str, float]
    frame_rate_hz: float

    @classmethod
    def read(cls, state: AppState) -> Planning:
        motion = state.devices.motion
        rates = {n: a.max_rate for n, a in motion.axes.items()} if motion else {}
        try:
            start = motion.status().positions if motion else {}
        except Exception:
            start = {}
        return cls(start, rates, state.devices.camera.get_settings().frame_rate_hz)

    def estimate_s(self, row: CampaignRow) -> float:
        pending = [sp for sp in row.setpoints if sp.status != "done"]
        return campaign_plan.estimate_duration_s(
            [setpoint_axes(sp) for sp in pending], self.start, self.rates,
            settle_s=row.settle_s, frames_per_point=row.frames_per_point,
            frame_rate_hz=self.frame_rate_hz,
            dynamic_s=[_dynamic_s(sp.profile) for sp in pending],
        )  # fmt: skip


def _dynamic_s(spec: dict | None) -> float | None:
    """A dynamic set-point's profile and rests (s), None at a static one."""
    if not spec:
        return None
    accel = spec.get("accel_deg_s2") or 1.0e9  # a ramp at the axis' limit: ramps ignored
    return profile_from_spec(spec, accel).duration_s + 2 * float(spec.get("rest_s", 2.0))


def _public(
    state: AppState, row: CampaignRow, planning: Planning | None = None, *,
    with_setpoints: bool = False,
) -> CampaignPublic:  # fmt: skip
    planning = planning or Planning.read(state)
    return campaign_public(row, state.campaigns.progress(row.id), planning.estimate_s(row),
                           with_setpoints=with_setpoints)  # fmt: skip


def _row(session, campaign_id: int) -> CampaignRow:
    row = session.get(CampaignRow, campaign_id)
    if row is None:
        raise HTTPException(404, f"no campaign with id {campaign_id}")
    return row


@router.post(
    "", status_code=status.HTTP_201_CREATED, dependencies=[WriteAuth], responses=errors(409)
)
def create_campaign(body: CampaignCreate, state: StateDep, session: SessionDep) -> CampaignPublic:
    """Store a draft campaign (start it with ``POST /api/campaigns/{id}/start``).

    422 names every problem: no set-points, both or neither of ``setpoints`` and
    ``generator``, set-points outside the soft limits, too many set-points or frames, an
    unknown catalog. 409 if the name is taken. Nothing is stored on an error.
    """
    if body.setpoints is not None and body.generator is not None:
        raise unprocessable(["body"], ["give either 'setpoints' or 'generator', not both"])
    try:
        setpoints = expand(body)
    except ValueError as exc:
        raise unprocessable(["body", "generator"], [str(exc)]) from exc
    motion = state.devices.motion
    problems = plan_problems(
        setpoints, motion.axes if motion else None, frames_per_point=body.frames_per_point,
        max_setpoints=MAX_SETPOINTS, max_frames=MAX_FRAMES_PER_CAMPAIGN,
    )  # fmt: skip
    if find_catalog(session, body.catalog) is None:
        problems.append(f"no catalog named {body.catalog!r} (GET /api/catalogs lists them)")
    spec = dynamic_spec(body)
    if spec is not None and motion is not None and "accel_deg_s2" not in spec:
        limits = motion.axes.get(spec["axis"])  # a ramp at the axis' limit, stored as such
        if spec["kind"] == "ramp" and limits is not None and limits.max_accel is not None:
            spec["accel_deg_s2"] = float(limits.max_accel)
    located = profile_plan_problems(setpoints, spec, motion) if spec is not None else []
    if problems or located:
        raise unprocessable_at([(["body"], p) for p in problems] + located)
    try:
        row = store_campaign(
            session, name=body.name, catalog_name=body.catalog, setpoints=setpoints,
            frames_per_point=body.frames_per_point, settle_s=body.settle_s,
            lock_timeout_s=body.lock_timeout_s, requirements=body.requirements.model_dump(),
            generator=body.generator.model_dump() if body.generator else None,
            camera=body.camera.model_dump(exclude_none=True) if body.camera else None,
            notes=body.notes, record_raw=body.record_raw,
            profiles=[spec] * len(setpoints) if spec is not None else None,
        )  # fmt: skip
    except NameTakenError as exc:
        raise HTTPException(409, str(exc)) from exc
    return _public(state, row, with_setpoints=True)


@router.get("", dependencies=[ReadAuth])
def list_campaigns(state: StateDep, session: SessionDep) -> list[CampaignPublic]:
    """Every campaign, newest first, without its set-point list."""
    rows = session.scalars(select(CampaignRow).order_by(CampaignRow.id.desc())).all()
    planning = Planning.read(state)
    return [_public(state, r, planning) for r in rows]


@router.get("/{campaign_id}", dependencies=[ReadAuth], responses=errors(404))
def get_campaign(campaign_id: IdParam, state: StateDep, session: SessionDep) -> CampaignPublic:
    """One campaign with its set-points and, while it runs, its progress."""
    return _public(state, _row(session, campaign_id), with_setpoints=True)


def _command(state: AppState, session, campaign_id: int, fn) -> CampaignPublic:
    _row(session, campaign_id)
    try:
        fn()
    except CampaignNotFoundError as exc:
        raise HTTPException(404, str(exc)) from exc
    except CampaignConflictError as exc:
        raise HTTPException(409, str(exc)) from exc
    session.expire_all()
    return _public(state, _row(session, campaign_id), with_setpoints=True)


@router.post("/{campaign_id}/start", dependencies=[WriteAuth], responses=errors(404, 409))
def start_campaign(
    campaign_id: IdParam, state: StateDep, session: SessionDep, body: CampaignStart | None = None
) -> CampaignPublic:
    """Queue the campaign: it runs as soon as the motion system is free, or at ``at``."""
    body = body or CampaignStart()
    return _command(
        state, session, campaign_id,
        lambda: state.campaigns.start_campaign(campaign_id, body.at, queue=body.queue),
    )  # fmt: skip


@router.post("/{campaign_id}/pause", dependencies=[WriteAuth], responses=errors(404, 409))
def pause_campaign(campaign_id: IdParam, state: StateDep, session: SessionDep) -> CampaignPublic:
    """Pause a running (or queued) campaign; the set-point in progress is measured again
    on resume."""
    return _command(state, session, campaign_id, lambda: state.campaigns.pause(campaign_id))


@router.post("/{campaign_id}/resume", dependencies=[WriteAuth], responses=errors(404, 409))
def resume_campaign(campaign_id: IdParam, state: StateDep, session: SessionDep) -> CampaignPublic:
    """Queue a paused or interrupted campaign again; it continues at its first set-point
    not done."""
    return _command(state, session, campaign_id, lambda: state.campaigns.resume(campaign_id))


@router.post("/{campaign_id}/cancel", dependencies=[WriteAuth], responses=errors(404, 409))
def cancel_campaign(campaign_id: IdParam, state: StateDep, session: SessionDep) -> CampaignPublic:
    """Cancel for good (what was measured stays stored and reportable)."""
    return _command(state, session, campaign_id, lambda: state.campaigns.cancel(campaign_id))


@router.get("/{campaign_id}/measurements", dependencies=[ReadAuth], responses=errors(404))
def list_measurements(
    campaign_id: IdParam,
    session: SessionDep,
    offset: Annotated[int, Query(ge=0, le=10_000_000)] = 0,
    limit: Annotated[int, Query(ge=1, le=10_000)] = 1000,
) -> MeasurementPage:
    """Stored frames of the campaign, in set-point then frame order, a page at a time."""
    _row(session, campaign_id)
    base = (
        select(MeasurementRow, SetPointRow.index)
        .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
        .where(SetPointRow.campaign_id == campaign_id)
    )
    total = session.scalar(select(func.count()).select_from(base.subquery()))
    rows = session.execute(
        base.order_by(SetPointRow.index, MeasurementRow.id).offset(offset).limit(limit)
    ).all()
    return MeasurementPage(
        total=total, offset=offset, items=[measurement_public(m, i) for m, i in rows]
    )


class ReportFormat(StrEnum):
    html = "html"
    pdf = "pdf"
    csv = "csv"
    json = "json"


class Reference(StrEnum):
    lab = "lab"
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
    },
)
def get_campaign_report(
    campaign_id: IdParam,
    fmt: ReportFormat,
    session: SessionDep,
    reference: Annotated[
        Reference, Query(description="lab: encoders + nominal geometry; exact: simulator only")
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
    (every statistic). Statistics against the lab's reference by default."""
    row = _row(session, campaign_id)
    cal = None
    if calibration is not None and (cal := session.get(CalibrationRow, calibration)) is None:
        raise HTTPException(404, f"no calibration with id {calibration}")
    try:
        report, rows = build(session, campaign_id, reference.value, cal)
    except ReportError as exc:
        raise unprocessable(["query", "reference"], [str(exc)]) from exc
    if fmt is ReportFormat.csv:
        body: str | bytes = to_csv(rows)
    elif fmt is ReportFormat.json:
        body = to_json(report)
    elif fmt is ReportFormat.html:
        body = to_html(report, rows)
    else:
        body = to_pdf(report, rows)
    filename = f"campaign-{row.id}-report.{fmt.value}"
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
    responses={200: {"content": {"application/x-hdf5": {}}, "description": "the recording"},
               **errors(404, 409)},
)  # fmt: skip
def get_campaign_recording(campaign_id: IdParam, state: StateDep, session: SessionDep):
    """The campaign's raw frames (HDF5, docs/architecture.md §7): exactly the stored
    measurements, in order (``recording_index`` of each). Only with ``record_raw``."""
    path = finished_recording(session, state, campaign_id)
    return FileResponse(path, media_type="application/x-hdf5",
                        filename=f"campaign-{campaign_id}.h5")  # fmt: skip


@router.get(
    "/{campaign_id}/recording.mcap",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={200: {"content": {"application/x-mcap": {}}, "description": "the recording"},
               **errors(404, 409)},
)  # fmt: skip
def get_campaign_recording_mcap(campaign_id: IdParam, state: StateDep, session: SessionDep):
    """The campaign's raw recording as MCAP for Foxglove and Rerun (docs/interop.md): the
    frames, the references and an estimate of each frame by the pipeline re-run over the
    recording (its camera and catalog, default settings, tracking off; not the stored
    measurement rows). Made on the first request (a long recording
    takes a while) and kept. Only with ``record_raw``."""
    path = finished_recording(session, state, campaign_id)
    return FileResponse(recording_mcap(path), media_type="application/x-mcap",
                        filename=f"campaign-{campaign_id}.mcap")  # fmt: skip
