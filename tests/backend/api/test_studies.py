"""Studies through the API: submitting needs the token; a study runs on a LocalCluster
to complete with the report downloadable; a bad spec is a 422 naming the field and
stores nothing; an unreachable scheduler fails the study naming its address; cancel.
Limits: a spec with too many cells or frames is refused from its axis lengths (no cell
made, almost no memory), too many active studies is a 409, and reading the largest
accepted study makes nothing of its grid."""

from __future__ import annotations

import json
import time
import tracemalloc

import pytest

from backend.services.jobs.batch_queue import BatchQueue
from backend.services.jobs.studies import StudyService, TooManyStudiesError, study_limits
from backend.settings import Settings
from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tofpose.sim.randomise import FAMILIES
from tofpose.study import run as study_run
from tofpose.study.run import StudyCancelledError
from tofpose.study.spec import Cell, StudySpec, StudySpecError
from tofpose.study.store import read_manifest, write_manifest

SPEC = {
    "name": "api",
    "seed": 5,
    "frames_per_cell": 2,
    "chunk_frames": 1,
    "grid": {"range_m": [2.0, 4.0]},
}
#: 64 x 64 x 64 x 7 = 1,835,008 cells: 64 values is the most the schema takes on an axis
HUGE = {
    "name": "huge",
    "frames_per_cell": 1,
    "grid": {
        "range_m": [1.0 + 0.25 * i for i in range(64)],
        "attitude_deg": [0.5 * i for i in range(64)],
        "offset_fraction": [0.01 * i for i in range(64)],
        "physics": list(FAMILIES),
    },
}
HUGE_CELLS = 64**3 * len(FAMILIES)


@pytest.fixture
def grid_built(monkeypatch) -> dict[str, int]:
    """Counts what building a study's grid makes while the test runs: ``Cell`` objects
    and chunk lists (``StudySpec.chunks``)."""
    made = {"cells": 0, "chunk lists": 0}
    init, chunks = Cell.__init__, StudySpec.chunks

    def cell(self, *args):
        made["cells"] += 1
        init(self, *args)

    def chunk_list(self):
        made["chunk lists"] += 1
        return chunks(self)

    monkeypatch.setattr(Cell, "__init__", cell)
    monkeypatch.setattr(StudySpec, "chunks", chunk_list)
    return made


@pytest.fixture
def held_runs(monkeypatch) -> None:
    """Studies run without a cluster: a run says ``running`` and holds the queue until it
    is cancelled or the server stops, then leaves the store ``incomplete`` like a real
    one (``tofpose.study.run``)."""

    def held(spec, out_dir, *, should_stop, **_):
        m = read_manifest(out_dir)
        write_manifest(out_dir, {**m, "status": "running"})
        while not should_stop():
            time.sleep(0.01)
        write_manifest(out_dir, {**read_manifest(out_dir), "status": "incomplete"})
        raise StudyCancelledError("held run stopped")

    # the service imports run_study when a study runs (docs/server.md, "Memory")
    monkeypatch.setattr(study_run, "run_study", held)


def test_a_study_runs_to_its_report(tmp_path):
    settings = make_settings(tmp_path / "data", dask_scheduler="", study_workers=1)
    with running_app(settings) as c:
        assert c.post("/api/studies", json=SPEC).status_code == 401  # moves no hardware,
        # but it takes the machine: a write like any other
        r = c.post("/api/studies", json=SPEC, headers=AUTH)
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert r.json()["frames_planned"] == 4 and r.json()["status"] in ("queued", "running")

        def finished():
            s = c.get(f"/api/studies/{sid}").json()
            return s if s["status"] in ("complete", "failed") else None

        done = wait_for(finished, timeout_s=240, what="the study")
        assert done["status"] == "complete", done
        assert done["frames_done"] == 4 and done["chunks_done"] == 4
        assert sorted(done["reports"]) == ["html", "json", "pdf"]
        summary = c.get(f"/api/studies/{sid}/report.json").json()
        assert [cell["range_m"] for cell in summary["cells"]] == [2.0, 4.0]
        assert summary["cells"][0]["success_pct"] == 100.0
        page = c.get(f"/api/studies/{sid}/report.html")
        assert page.headers["content-type"].startswith("text/html")
        assert 'src="plots/success_map.png"' in page.text
        png = c.get(f"/api/studies/{sid}/plots/success_map.png")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
        assert c.get(f"/api/studies/{sid}/report.pdf").content[:4] == b"%PDF"
        assert [s["id"] for s in c.get("/api/studies").json()] == [sid]


def test_bad_specs_are_named_and_nothing_is_stored(client):
    bad = [
        ({**SPEC, "grid": {"range_m": [0.1]}}, ["body", "grid", "range_m", 0]),
        ({**SPEC, "grid": {"range_m": [3.0, 3.0]}}, ["body", "grid", "range_m"]),
        ({**SPEC, "grid": {"catalog": ["nope"]}}, ["body", "grid", "catalog", 0]),
        ({**SPEC, "colour": "red"}, ["body", "colour"]),
        (
            {
                **SPEC,
                "frames_per_cell": 10**6,
                "grid": {
                    "range_m": [1.0 + 0.25 * i for i in range(64)],
                    "attitude_deg": [1.0, 2.0],
                },
            },
            ["body", "frames_per_cell"],
        ),
    ]
    for body, loc in bad:
        r = client.post("/api/studies", json=body, headers=AUTH)
        assert r.status_code == 422, (body, r.text)
        assert any(d["loc"] == loc for d in r.json()["detail"]), (loc, r.json())
    assert client.get("/api/studies").json() == []
    assert client.get("/api/studies/7").status_code == 404
    assert client.get("/api/studies/7/report.html").status_code == 404


def test_an_unreachable_scheduler_fails_the_study_naming_it(client):
    sid = client.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]
    s = wait_for(
        lambda: (x := client.get(f"/api/studies/{sid}").json())["status"] == "failed" and x,
        timeout_s=60,
        what="the study to fail",
    )
    assert "tcp://127.0.0.1:9" in s["error"]
    assert client.get(f"/api/studies/{sid}/report.html").status_code == 409


def test_a_queued_study_can_be_cancelled(client):
    first = client.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]
    second = client.post("/api/studies", json={**SPEC, "name": "second"}, headers=AUTH).json()
    assert client.post(f"/api/studies/{second['id']}/cancel").status_code == 401
    r = client.post(f"/api/studies/{second['id']}/cancel", headers=AUTH)
    assert r.status_code == 200 and r.json()["status"] == "incomplete"
    wait_for(
        lambda: client.get(f"/api/studies/{first}").json()["status"] == "failed",
        timeout_s=60,
        what="the first study to end",
    )
    # the cancelled one never ran
    assert client.get(f"/api/studies/{second['id']}").json()["status"] == "incomplete"
    assert json.loads(json.dumps(client.get("/api/studies").json()))[0]["name"] == "second"


def test_too_many_cells_or_frames_are_refused_naming_the_limit_and_the_numbers(held_runs, client):
    r = client.post("/api/studies", json=HUGE, headers=AUTH)
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == [
        {
            "loc": ["body", "grid"],
            "type": "value_error",
            "msg": "1,835,008 cells (64 range_m x 64 attitude_deg x 64 offset_fraction x 7 "
            "physics) "
            "is more than the limit of 10,000 (TOFPOSE_STUDY_MAX_CELLS)",
        }
    ]
    frames = {**SPEC, "frames_per_cell": 600_000}  # 2 cells: 1.2 M frames
    r = client.post("/api/studies", json=frames, headers=AUTH)
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == [
        {
            "loc": ["body", "frames_per_cell"],
            "type": "value_error",
            "msg": "2 cells x 600,000 frames = 1,200,000 frames is more than the limit of "
            "1,000,000 "
            "(TOFPOSE_STUDY_MAX_FRAMES)",
        }
    ]
    at_limit = {**SPEC, "frames_per_cell": 500_000, "chunk_frames": 100_000}  # 10^6 frames
    r = client.post("/api/studies", json=at_limit, headers=AUTH)
    assert r.status_code == 201 and r.json()["frames_planned"] == 1_000_000, r.text


def test_refusing_a_huge_grid_makes_nothing_of_it_and_stores_nothing(client, grid_built):
    tofpose = client.app.state.tofpose
    tofpose.acquisition.stop()  # the live loop's frames would count in the peak below
    small = {**HUGE, "grid": {**HUGE["grid"], "range_m": [2.0, 4.0]}}  # 57,344 cells
    assert client.post("/api/studies", json=small, headers=AUTH).status_code == 422  # warm
    tracemalloc.start()
    try:
        r = client.post("/api/studies", json=HUGE, headers=AUTH)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert r.status_code == 422 and f"{HUGE_CELLS:,} cells" in r.json()["detail"][0]["msg"]
    assert grid_built == {"cells": 0, "chunk lists": 0}
    assert peak < 1_000_000  # bytes, the whole request; building the grid took ~350 MB
    assert client.get("/api/studies").json() == []
    assert not any(tofpose.studies.root.iterdir())


def test_reading_the_largest_accepted_study_makes_nothing_of_its_grid(
    tmp_path, held_runs, grid_built
):
    settings = make_settings(
        tmp_path / "data", study_max_cells=HUGE_CELLS, study_max_frames=HUGE_CELLS
    )
    with running_app(settings) as c:
        r = c.post("/api/studies", json=HUGE, headers=AUTH)
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        wait_for(
            lambda: c.get(f"/api/studies/{sid}").json()["status"] == "running", what="the held run"
        )
        for _ in range(3):
            one = c.get(f"/api/studies/{sid}").json()
            (listed,) = c.get("/api/studies").json()
            assert listed == one
            assert (one["cells"], one["frames_planned"], one["chunks"]) == (HUGE_CELLS,) * 3
        assert grid_built == {"cells": 0, "chunk lists": 0}  # nor when it was submitted
        assert c.post(f"/api/studies/{sid}/cancel", headers=AUTH).status_code == 200
        wait_for(
            lambda: c.get(f"/api/studies/{sid}").json()["status"] == "incomplete",
            what="the cancelled run to end",
        )


def test_too_many_active_studies_is_409_until_one_ends(tmp_path, held_runs):
    settings = make_settings(tmp_path / "data", studies_max_active=2)
    with running_app(settings) as c:
        first = c.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]
        second = c.post("/api/studies", json={**SPEC, "name": "b"}, headers=AUTH).json()["id"]
        wait_for(
            lambda: c.get(f"/api/studies/{first}").json()["status"] == "running",
            what="the first study to run",
        )
        r = c.post("/api/studies", json={**SPEC, "name": "c"}, headers=AUTH)
        assert r.status_code == 409, r.text
        assert r.json()["detail"] == (
            "2 studies are queued or running, the limit is 2 "
            "(TOFPOSE_STUDIES_MAX_ACTIVE): cancel one or wait for "
            "one to end"
        )
        assert [s["id"] for s in c.get("/api/studies").json()] == [second, first]  # none stored
        cancelled = c.post(f"/api/studies/{second}/cancel", headers=AUTH).json()
        assert cancelled["status"] == "incomplete"
        r = c.post("/api/studies", json={**SPEC, "name": "c"}, headers=AUTH)
        assert r.status_code == 201 and r.json()["status"] == "queued", r.text
        assert c.post("/api/studies", json=SPEC, headers=AUTH).status_code == 409


def test_the_variables_a_refusal_names_are_the_ones_that_set_the_limits(monkeypatch, tmp_path):
    monkeypatch.setenv("TOFPOSE_STUDY_MAX_CELLS", "3")
    monkeypatch.setenv("TOFPOSE_STUDY_MAX_FRAMES", "7")
    monkeypatch.setenv("TOFPOSE_STUDIES_MAX_ACTIVE", "1")
    settings = Settings(data_dir=tmp_path)
    four_cells = {"frames_per_cell": 1, "grid": {"range_m": [2.0, 4.0, 6.0, 8.0]}}
    with pytest.raises(StudySpecError, match=r"limit of 3 \(TOFPOSE_STUDY_MAX_CELLS\)$"):
        StudySpec.from_dict(four_cells, study_limits(settings))
    with pytest.raises(StudySpecError, match=r"= 8 frames .* 7 \(TOFPOSE_STUDY_MAX_FRAMES\)$"):
        StudySpec.from_dict({**SPEC, "frames_per_cell": 4}, study_limits(settings))
    service = StudyService(tmp_path / "studies", jobs=BatchQueue())  # its queue never runs
    spec = StudySpec.from_dict(SPEC, study_limits(settings))
    assert service.submit(spec, max_active=settings.studies_max_active) == 1
    with pytest.raises(TooManyStudiesError, match=r"limit is 1 \(TOFPOSE_STUDIES_MAX_ACTIVE\)"):
        service.submit(spec, max_active=settings.studies_max_active)
