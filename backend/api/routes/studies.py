"""Monte-Carlo accuracy studies on Dask (docs/scaleout.md): submit, list, follow,
cancel, download the report."""

from __future__ import annotations

from dataclasses import asdict
from typing import Literal

from fastapi import APIRouter, HTTPException, status
from fastapi.responses import FileResponse

from backend.api.contract import errors
from backend.api.deps import ReadAuth, StateDep, WriteAuth, unprocessable
from backend.api.schemas.studies import StudyCreate, StudyPublic
from backend.services.jobs.studies import study_limits
from tofpose.study.spec import StudySpec, StudySpecError

router = APIRouter(prefix="/api/studies", tags=["studies"])

PlotName = Literal["attitude_vs_range.png", "success_map.png", "consistency_vs_range.png"]
MEDIA = {"html": "text/html", "pdf": "application/pdf", "json": "application/json"}


def _public(s) -> StudyPublic:
    # fields the status has and the answer does not are left out; ``dashboard_url`` is
    # passed on when the job service's status carries one (Dask runs)
    fields = {**asdict(s), "reports": list(s.reports)}
    return StudyPublic(**{k: v for k, v in fields.items() if k in StudyPublic.model_fields})


@router.post(
    "", status_code=status.HTTP_201_CREATED, dependencies=[WriteAuth], responses=errors(409)
)
def create_study(body: StudyCreate, state: StateDep) -> StudyPublic:
    """Queue a study. ``requirements`` (optional, each field optional: the campaign's
    defaults, 95 % of a cell's frames) is what each cell's verdict in the report is
    judged against. 422 names the field when the spec cannot run (a range outside
    0.3-20 m, an unknown catalog, a value listed twice, a requirement <= 0, more cells
    or frames than the
    server takes: TOFPOSE_STUDY_MAX_CELLS, TOFPOSE_STUDY_MAX_FRAMES); 409 while
    TOFPOSE_STUDIES_MAX_ACTIVE studies are queued or running. Nothing is stored then."""
    doc = body.model_dump(exclude_none=True)
    doc["grid"] = body.grid.model_dump(exclude_none=True)
    doc["requirements"] = body.requirements.model_dump()
    try:  # the size is checked from the axis lengths before anything is made
        spec = StudySpec.from_dict(doc, limits=study_limits(state.settings))
    except StudySpecError as exc:
        raise unprocessable(["body", *exc.loc], [exc.problem]) from exc
    sid = state.studies.submit(spec, max_active=state.settings.studies_max_active)
    return _public(state.studies.status(sid))


@router.get("", dependencies=[ReadAuth])
def list_studies(state: StateDep) -> list[StudyPublic]:
    """Every study, newest first, with its progress."""
    return [_public(s) for s in state.studies.list()]


@router.get("/{study_id}", dependencies=[ReadAuth], responses=errors(404))
def get_study(study_id: int, state: StateDep) -> StudyPublic:
    """A study's status, progress (frames and chunks done) and ETA."""
    return _public(state.studies.status(study_id))


@router.post("/{study_id}/cancel", dependencies=[WriteAuth], responses=errors(404))
def cancel_study(study_id: int, state: StateDep) -> StudyPublic:
    """Stop a queued or running study; the chunks it finished stay (status
    ``incomplete``). A finished study is returned as it is."""
    return _public(state.studies.cancel(study_id))


@router.get(
    "/{study_id}/report.{fmt}",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={**errors(404, 409), 200: {"content": {m: {} for m in MEDIA.values()}}},
)
def study_report(study_id: int, fmt: Literal["html", "pdf", "json"], state: StateDep):
    """The study's report: ``html`` (shown in the browser, its plots from ``plots/``),
    ``pdf``, or ``json``
    (summary.json, the per-cell statistics). 409 until the study is complete."""
    path = state.studies.report_path(study_id, fmt)
    if path is None:
        raise HTTPException(409, f"study {study_id} has no {fmt} report yet (it is not complete)")
    # the HTML opens in the browser (its plots load relative to it); the others download
    return FileResponse(
        path,
        media_type=MEDIA[fmt],
        filename=f"study-{study_id}.{fmt}",
        content_disposition_type="inline" if fmt == "html" else "attachment",
    )


@router.get(
    "/{study_id}/plots/{name}",
    dependencies=[ReadAuth],
    response_class=FileResponse,
    responses={**errors(404), 200: {"content": {"image/png": {}}}},
)
def study_plot(study_id: int, name: PlotName, state: StateDep):
    """A plot of the report (report.html links them relative to itself)."""
    path = state.studies.report_path(study_id, "html")
    plot = None if path is None else path.parent / "plots" / name
    if plot is None or not plot.exists():
        raise HTTPException(404, f"study {study_id} has no plot {name}")
    return FileResponse(plot, media_type="image/png")
