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


def _record_from_the_page(page, name: str) -> int:
    """Start a recording named ``name`` in the Record panel; its id once it runs."""
    page.get_by_test_id("rec-name").fill(name)
    page.get_by_test_id("rec-start").click()
    live = page.locator("[data-testid^=rec-live-]")
    live.wait_for(timeout=15_000)
    return int(live.get_attribute("data-testid").rsplit("-", 1)[1])


def test_record_from_the_page_stop_download_and_read_it(server, page_for, tmp_path):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("rec-name").wait_for(timeout=20_000)
    assert "GB free on the server's data disk" in page.get_by_test_id("rec-disk").inner_text()

    page.get_by_test_id("rec-start").click()  # no name: refused on the page, nothing sent
    assert "name" in page.get_by_test_id("rec-field-error").inner_text()
    assert httpx.get(server.base_url + "/api/recordings").json()["recordings"] == []

    rid = _record_from_the_page(page, "from the page")
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


def test_the_camera_panel_says_why_the_frequency_holds_while_recording(server, page_for):
    """While a recording records, the camera panel says which recording holds the
    modulation frequency and its field is disabled (the other settings stay open); a
    frequency typed before the start and applied anyway is refused, and the error banner
    says why in view of the panel (under the sticky header) until dismissed; the camera
    stays at 6 MHz. After the stop the field opens and the same change is applied."""
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("rec-name").wait_for(timeout=20_000)
    page.get_by_test_id("cam-modulation_frequency_mhz").fill("12")  # typed, not applied yet
    rid = _record_from_the_page(page, "held frequency")

    notice = page.get_by_test_id("cam-frequency-held")
    notice.wait_for(timeout=10_000)  # the panel polls every 2 s
    assert f"recording {rid} ('held frequency')" in notice.inner_text()
    assert page.get_by_test_id("cam-modulation_frequency_mhz").is_disabled()
    assert page.get_by_test_id("cam-integration_time_us").is_enabled()
    page.get_by_test_id("cam-apply").click()
    error = page.get_by_test_id("error")
    error.wait_for(timeout=10_000)
    text = error.inner_text()
    assert f"recording {rid} ('held frequency')" in text and "stop it" in text, text
    # the banner stays in view beside the panel the user is at (the page is scrolled to
    # the camera panel), until dismissed
    assert error.is_visible() and error.bounding_box()["y"] < 120
    page.screenshot(path=SHOTS / "camera-frequency-held-while-recording.png")
    page.get_by_test_id("error-dismiss").click()
    assert page.get_by_test_id("error").count() == 0
    settings = httpx.get(server.base_url + "/api/camera/settings").json()
    assert settings["modulation_frequency_mhz"] == 6

    page.get_by_test_id(f"rec-stop-{rid}").click()
    page.get_by_test_id(f"rec-h5-{rid}").wait_for(timeout=15_000)
    wait_for(lambda: notice.count() == 0, 10.0, "the notice to go")
    assert page.get_by_test_id("cam-modulation_frequency_mhz").is_enabled()
    page.get_by_test_id("cam-apply").click()  # the field still says 12
    wait_for(
        lambda: (
            httpx.get(server.base_url + "/api/camera/settings").json()["modulation_frequency_mhz"]
            == 12
        ),
        10.0,
        "12 MHz applied",
    )
