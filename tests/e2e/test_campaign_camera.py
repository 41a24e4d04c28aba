"""A campaign with an integration-time sweep and metadata made in the page: the form sends
the sweep and the metadata typed (checked through the API), the draft lists each
set-point's camera setting, the campaign runs on the simulated lab, and its result shows
the metadata and the statistics per integration time; a time beyond the camera's limits
is refused naming the field and the range, and nothing is created."""

from __future__ import annotations

import httpx
import pytest

from tests.backend.conftest import AUTH, TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS
from tofpose import __version__


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data", sim_time_scale=5.0)) as srv:
        yield srv


def _get(server, path: str):
    r = httpx.get(f"{server.base_url}{path}", headers=AUTH, timeout=30.0)
    r.raise_for_status()
    return r.json()


def _fill(page, name: str, times: str) -> None:
    page.get_by_test_id("new-name").fill(name)
    page.get_by_test_id("new-rail_mm").fill("13000")
    page.get_by_test_id("new-frames").fill("4")
    page.get_by_test_id("new-integration").fill(times)
    page.get_by_test_id("new-operator").fill("A. Operator")
    page.get_by_test_id("new-target_name").fill("paper target #2")
    page.get_by_test_id("new-camera_serial").fill("EPC-0042")
    page.get_by_test_id("new-notes").fill("exposure sweep for the range calibration")


def test_an_integration_time_sweep_with_metadata_made_in_the_page_runs(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    _fill(page, "page-exposure", "100, 400")
    page.get_by_test_id("new-create").click()
    draft = page.get_by_test_id("draft")
    draft.wait_for(timeout=10_000)
    assert "2 set-points" in draft.inner_text()
    assert page.get_by_test_id("draft-camera-0").inner_text() == "100 us"
    assert page.get_by_test_id("draft-camera-1").inner_text() == "400 us"
    page.get_by_test_id("new-campaign").screenshot(path=str(SHOTS / "campaign-camera-form.png"))
    cid = int(draft.inner_text().split("Draft ")[1].split()[0])
    stored = _get(server, f"/api/campaigns/{cid}")
    assert stored["camera_sweep"] == {"integration_time_us": [100.0, 400.0]}
    assert (stored["operator"], stored["target_name"], stored["camera_serial"]) == (
        "A. Operator",
        "paper target #2",
        "EPC-0042",
    )
    assert stored["camera_firmware"] == __version__  # the simulator's, read from it
    assert stored["notes"] == "exposure sweep for the range calibration"

    page.get_by_test_id(f"start-{cid}").click()
    page.wait_for_function(
        f"document.querySelector('[data-testid=status-{cid}]').innerText === 'done'",
        timeout=120_000,
    )
    assert page.get_by_test_id(f"operator-{cid}").inner_text() == " (A. Operator)"
    report = _get(server, f"/api/campaigns/{cid}/report.json")
    page.get_by_test_id(f"results-{cid}").click()
    meta = page.get_by_test_id(f"metadata-{cid}")
    meta.wait_for(timeout=30_000)
    text = meta.inner_text()
    for needle in ("A. Operator", "paper target #2", "EPC-0042", __version__, "exposure sweep"):
        assert needle in text, (needle, text)
    rows = page.get_by_test_id(f"camera-settings-{cid}").locator("tbody tr")
    assert rows.count() == 2
    for k, g in enumerate(report["camera_settings"]):
        cells = rows.nth(k).inner_text().split("\t")
        assert cells[0] == f"{g['setting']['integration_time_us']:g} us"
        assert cells[2] == f"{g['range_error_mean_mm']:.2f}"
    inner = page.frame_locator(f"iframe[title='campaign {cid} report']")
    inner.locator("img").first.wait_for(timeout=60_000)
    page.get_by_test_id(f"result-{cid}").scroll_into_view_if_needed()
    page.screenshot(path=str(SHOTS / "campaign-camera-result.png"))


def test_an_integration_time_beyond_the_limits_is_refused_naming_field_and_range(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    _fill(page, "too-long", "100, 5000")
    page.get_by_test_id("new-create").click()
    err = page.get_by_test_id("error")
    err.wait_for(timeout=10_000)
    text = err.inner_text()
    assert "422" in text and "body.camera_sweep.integration_time_us.1" in text, text
    assert "range 10 to 4000 us" in text, text
    assert page.get_by_test_id("draft").count() == 0
    assert _get(server, "/api/campaigns") == []
