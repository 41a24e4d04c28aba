"""A study's requirements through the API: a spec with requirements is accepted and
stored with them (the rest of the campaign's defaults filled in), a spec without them
gets the campaign's, a bad requirement is a 422 at its field and stores nothing; the
campaign's and the study's defaults are one definition; a status's ``dashboard_url`` is
passed on."""

from __future__ import annotations

import time
from dataclasses import dataclass

import pytest

from backend.api.routes.studies import _public
from backend.api.schemas.campaigns import Requirements
from backend.api.schemas.studies import StudyRequirements
from backend.services.reports import report_content
from tests.backend.conftest import AUTH
from tofpose.lab.requirements import PAPER_REQUIREMENTS, REQUIREMENT_AXES
from tofpose.study import run as study_run
from tofpose.study.run import StudyCancelledError
from tofpose.study.store import read_manifest, write_manifest

SPEC = {"name": "req", "frames_per_cell": 2, "chunk_frames": 1, "grid": {"range_m": [2.0, 4.0]}}


@pytest.fixture
def held_runs(monkeypatch) -> None:
    """Studies hold the queue as ``running`` until stopped (no cluster)."""

    def held(spec, out_dir, *, should_stop, **_):
        write_manifest(out_dir, {**read_manifest(out_dir), "status": "running"})
        while not should_stop():
            time.sleep(0.01)
        write_manifest(out_dir, {**read_manifest(out_dir), "status": "incomplete"})
        raise StudyCancelledError("held run stopped")

    # the service imports run_study when a study runs (docs/server.md, "Memory")
    monkeypatch.setattr(study_run, "run_study", held)


def _stored(settings, sid: int) -> dict:
    return read_manifest(settings.data_dir / "studies" / str(sid))["spec"]


def test_a_spec_with_requirements_is_accepted_and_stored_with_them(held_runs, settings, client):
    body = {**SPEC, "requirements": {"z_mm": 40.0, "pitch_deg": 0.3, "percentile": 99}}
    r = client.post("/api/studies", json=body, headers=AUTH)
    assert r.status_code == 201, r.text
    req = _stored(settings, r.json()["id"])["requirements"]
    assert req == {**PAPER_REQUIREMENTS, "z_mm": 40.0, "pitch_deg": 0.3, "percentile": 99.0}
    client.post(f"/api/studies/{r.json()['id']}/cancel", headers=AUTH)
    r = client.post("/api/studies", json=SPEC, headers=AUTH)
    assert r.status_code == 201, r.text
    assert _stored(settings, r.json()["id"])["requirements"] == {
        **PAPER_REQUIREMENTS,
        "percentile": 95.0,
    }


@pytest.mark.parametrize(
    ("requirements", "loc"),
    [
        ({"pitch_deg": 0}, ["body", "requirements", "pitch_deg"]),
        ({"z_mm": -1}, ["body", "requirements", "z_mm"]),
        ({"percentile": 20}, ["body", "requirements", "percentile"]),
        ({"pitch": 0.1}, ["body", "requirements", "pitch"]),
        ({"x_mm": "6"}, ["body", "requirements", "x_mm"]),
    ],
)
def test_a_bad_requirement_is_a_422_at_its_field_and_nothing_is_stored(
    held_runs, client, requirements, loc
):
    r = client.post("/api/studies", json={**SPEC, "requirements": requirements}, headers=AUTH)
    assert r.status_code == 422, r.text
    assert [d["loc"] for d in r.json()["detail"]] == [loc]
    assert client.get("/api/studies").json() == []


def test_campaigns_and_studies_default_to_the_same_requirements():
    campaign, study = Requirements(), StudyRequirements()
    for axis in REQUIREMENT_AXES:
        assert getattr(campaign, axis) == getattr(study, axis) == PAPER_REQUIREMENTS[axis]
    # the campaign report's own copy (backend/services/reports/report_content.py), which
    # says whether a campaign's requirements are the defaults, holds the same numbers
    assert report_content.PAPER_REQUIREMENTS is PAPER_REQUIREMENTS


def test_a_dashboard_url_in_the_status_is_passed_on():
    @dataclass(frozen=True)
    class Status:  # a job status as the Dask runs give it, with a field the API lacks
        id: int = 1
        name: str = "s"
        status: str = "running"
        cells: int = 2
        frames_planned: int = 4
        frames_done: int = 1
        chunks: int = 4
        chunks_done: int = 1
        eta_s: float | None = 3.0
        error: str | None = None
        started: str | None = None
        finished: str | None = None
        cluster: str | None = "LocalCluster(1)"
        reports: tuple[str, ...] = ()
        dashboard_url: str | None = "http://127.0.0.1:8787/status"
        worker_pids: tuple[int, ...] = (1, 2)

    assert _public(Status()).dashboard_url == "http://127.0.0.1:8787/status"
    assert _public(Status(dashboard_url=None)).dashboard_url is None
