"""Studies through the API: submitting needs the token; a study runs on a LocalCluster
to complete with the report downloadable; a bad spec is a 422 naming the field and
stores nothing; an unreachable scheduler fails the study naming its address; cancel."""

from __future__ import annotations

import json

from tests.backend.conftest import AUTH, make_settings, running_app, wait_for

SPEC = {"name": "api", "seed": 5, "frames_per_cell": 2, "chunk_frames": 1,
        "grid": {"range_m": [2.0, 4.0]}}  # fmt: skip


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
        ({**SPEC, "frames_per_cell": 10**6, "grid": {"range_m": [1.0 + 0.25 * i for i in range(64)],
                                                      "attitude_deg": [1.0, 2.0]}},
         ["body", "frames_per_cell"]),
    ]  # fmt: skip
    for body, loc in bad:
        r = client.post("/api/studies", json=body, headers=AUTH)
        assert r.status_code == 422, (body, r.text)
        assert any(d["loc"] == loc for d in r.json()["detail"]), (loc, r.json())
    assert client.get("/api/studies").json() == []
    assert client.get("/api/studies/7").status_code == 404
    assert client.get("/api/studies/7/report.html").status_code == 404


def test_an_unreachable_scheduler_fails_the_study_naming_it(client):
    sid = client.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]
    s = wait_for(lambda: (x := client.get(f"/api/studies/{sid}").json())["status"] == "failed"
                 and x, timeout_s=60, what="the study to fail")  # fmt: skip
    assert "tcp://127.0.0.1:9" in s["error"]
    assert client.get(f"/api/studies/{sid}/report.html").status_code == 409


def test_a_queued_study_can_be_cancelled(client):
    first = client.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]
    second = client.post("/api/studies", json={**SPEC, "name": "second"}, headers=AUTH).json()
    assert client.post(f"/api/studies/{second['id']}/cancel").status_code == 401
    r = client.post(f"/api/studies/{second['id']}/cancel", headers=AUTH)
    assert r.status_code == 200 and r.json()["status"] == "incomplete"
    wait_for(lambda: client.get(f"/api/studies/{first}").json()["status"] == "failed",
             timeout_s=60, what="the first study to end")  # fmt: skip
    # the cancelled one never ran
    assert client.get(f"/api/studies/{second['id']}").json()["status"] == "incomplete"
    assert json.loads(json.dumps(client.get("/api/studies").json()))[0]["name"] == "second"
