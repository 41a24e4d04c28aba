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
