"""A batch job's status while its cluster runs: the Dask dashboard's address
(``dashboard_url``, served by the scheduler), null before and after; a LocalCluster of
more workers than cores is said in the status (``warnings``)."""

from __future__ import annotations

import os

import httpx

from tests.backend.conftest import AUTH, make_settings, running_app, wait_for

SPEC = {
    "name": "dash",
    "seed": 5,
    "frames_per_cell": 48,
    "chunk_frames": 2,
    "grid": {"range_m": [2.0]},
}


def test_a_running_study_shows_its_dashboard_and_its_warning(tmp_path):
    cores = len(os.sched_getaffinity(0))
    settings = make_settings(tmp_path / "data", dask_scheduler="", study_workers=cores + 1)
    with running_app(settings) as c:
        sid = c.post("/api/studies", json=SPEC, headers=AUTH).json()["id"]

        def running_with_dashboard():
            s = c.get(f"/api/studies/{sid}").json()
            if s["status"] in ("complete", "failed"):
                raise AssertionError(f"the study ended before its status showed a dashboard: {s}")
            return s if s["status"] == "running" and s["dashboard_url"] else None

        running = wait_for(running_with_dashboard, timeout_s=240, what="a running study")
        url = running["dashboard_url"]
        assert url.startswith("http://127.0.0.1:")
        page = httpx.get(url, timeout=30)  # the scheduler's own pages
        assert page.status_code == 200 and "Worker" in page.text
        assert running["warnings"] == [
            f"{cores + 1} worker threads on {os.uname().nodename}, which has {cores} cores: "
            f"they share the cores, so each runs slower than a serial run (use at most "
            f"{cores} workers there)"
        ]

        def finished():
            s = c.get(f"/api/studies/{sid}").json()
            return s if s["status"] in ("complete", "failed") else None

        done = wait_for(finished, timeout_s=240, what="the study")
        assert done["status"] == "complete", done
        assert done["dashboard_url"] is None and done["warnings"] == running["warnings"]


def test_a_running_reprocessing_shows_its_dashboard_and_its_frames(tmp_path):
    from backend.services.jobs.reprocessing import ReprocessService
    from tofpose.cli import main

    rec = tmp_path / "campaign-1.h5"
    args = ["simulate", "--scenario", "range-sweep", "--frames", "120", "--out", str(rec)]
    assert main(args) == 0
    service = ReprocessService(tmp_path / "jobs", workers=1)
    service.start()
    try:
        jid = service.submit(1, rec, None, tracking=True)["id"]

        def running_with_dashboard():
            job = service.status(jid)
            if job["status"] in ("complete", "failed"):
                raise AssertionError(f"the job ended before its status showed a dashboard: {job}")
            return job if job["status"] == "running" and job["dashboard_url"] else None

        running = wait_for(running_with_dashboard, timeout_s=240, what="a running job")
        assert running["dashboard_url"].startswith("http://127.0.0.1:")
        assert running["warnings"] == []

        def finished():
            job = service.status(jid)
            return job if job["status"] in ("complete", "failed") else None

        seen = []

        def progress_then_finished():
            job = service.status(jid)
            if job["frames_done"] is not None:
                seen.append((job["frames_done"], job["frames_planned"]))
            return finished()

        done = wait_for(progress_then_finished, timeout_s=240, what="the job")
        assert done["status"] == "complete", done
        assert done["dashboard_url"] is None and done["frames_done"] is None
        assert all(0 <= d <= p == 240 for d, p in seen)
    finally:
        service.stop()
