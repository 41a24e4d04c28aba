"""The dashboard's Record panel: name a recording, record the live stream for ~2 s, watch
its frames and size grow, stop it, download the HDF5 from the list and read it with
``tofpose.io.recording``: the frames the server counted, stamped with the wall clock of now."""

from __future__ import annotations

import time

import h5py
import httpx
import numpy as np
import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings, wait_for
from tests.e2e.conftest import SHOTS
from tofpose.io.recording import open_recording


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data", recording_min_free_mb=100)) as srv:
        yield srv


def test_record_from_the_page_stop_download_and_read_it(server, page_for, tmp_path):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("rec-name").wait_for(timeout=20_000)
    assert "GB free on the server's data disk" in page.get_by_test_id("rec-disk").inner_text()

    page.get_by_test_id("rec-start").click()  # no name: refused on the page, nothing sent
    assert "name" in page.get_by_test_id("rec-field-error").inner_text()
    assert httpx.get(server.base_url + "/api/recordings").json()["recordings"] == []

    page.get_by_test_id("rec-name").fill("from the page")
    page.get_by_test_id("rec-start").click()
    live = page.locator("[data-testid^=rec-live-]")
    live.wait_for(timeout=15_000)
    rid = int(live.get_attribute("data-testid").rsplit("-", 1)[1])
    page.wait_for_timeout(2000)  # ~2 s of the live stream
    wait_for(
        lambda: float(page.get_by_test_id(f"rec-size-{rid}").inner_text()) > 0,
        15.0,
        "the size on the page",
    )
    assert int(page.get_by_test_id(f"rec-frames-{rid}").inner_text()) > 0
    page.get_by_test_id("recorder").screenshot(path=SHOTS / "recorder-running.png")

    page.get_by_test_id(f"rec-stop-{rid}").click()
    page.get_by_test_id(f"rec-h5-{rid}").wait_for(timeout=15_000)
    assert page.get_by_test_id(f"rec-state-{rid}").inner_text() == "stopped"
    assert page.locator("[data-testid^=rec-live-]").count() == 0
    page.get_by_test_id("recorder").screenshot(path=SHOTS / "recorder-stopped.png")
    page.screenshot(path=SHOTS / "dashboard-recorder.png")

    with page.expect_download() as download:
        page.get_by_test_id(f"rec-h5-{rid}").click()
    path = tmp_path / "from-the-page.h5"
    download.value.save_as(path)
    assert download.value.suggested_filename == f"from-the-page-{rid}.h5"

    entry = httpx.get(f"{server.base_url}/api/recordings/{rid}").json()
    assert (entry["name"], entry["state"], entry["stop_reason"]) == (
        "from the page",
        "stopped",
        "requested",
    )
    with open_recording(path) as rec:
        assert rec.n_frames == entry["frames"] > 0
        assert rec.reference_R is not None  # the simulated lab's reference, as in any recording
    with h5py.File(path, "r") as f:
        wall_s = f["frames/wall_time_ns"][...] / 1e9
        assert (np.abs(wall_s - time.time()) < 60).all()
        assert f["pose/ok"][...].any()
