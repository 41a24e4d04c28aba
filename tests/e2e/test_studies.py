"""Accuracy studies in the dashboard: a study built in the form (a range axis, a list,
physics, frames per cell, a requirement); the JSON view shows the same spec and its edits
come back to the form; a value the server refuses is named next to its field; the study
runs, shows its progress to complete, and its report opens with the verdict first."""

from __future__ import annotations

import json

import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS


@pytest.fixture
def server(tmp_path):
    settings = make_settings(tmp_path / "data", dask_scheduler="", study_workers=1)
    with LiveServer(settings) as srv:
        yield srv


def test_a_study_built_in_the_form_runs_and_its_report_leads_with_the_verdict(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_text("new study").click()
    page.get_by_test_id("study-name").fill("page")
    page.get_by_test_id("study-frames_per_cell").fill("3")
    page.get_by_test_id("study-chunk_frames").fill("1")
    # range as start / stop / step; a value listed twice is the server's to refuse
    page.get_by_test_id("study-range_m-mode").select_option("range")
    page.get_by_test_id("study-range_m-start").fill("2.5")
    page.get_by_test_id("study-range_m-stop").fill("5")
    page.get_by_test_id("study-range_m-step").fill("2.5")
    page.get_by_test_id("study-attitude_deg").fill("20, 20")
    page.get_by_test_id("study-physics-lens-blur").uncheck()
    page.get_by_test_id("study-physics-grey-plate").check()
    page.get_by_test_id("study-req-pitch_deg").fill("0.5")
    page.get_by_test_id("study-submit").click()
    err = page.get_by_test_id("study-error-grid.attitude_deg")
    err.wait_for(timeout=5000)
    assert "listed twice" in err.inner_text()
    # the message sits beside the field it names
    field_box = page.get_by_test_id("study-attitude_deg").bounding_box()
    err_box = err.bounding_box()
    assert field_box and err_box and abs(err_box["y"] - field_box["y"]) < 60
    page.get_by_test_id("new-study").screenshot(path=str(SHOTS / "study-form-error.png"))
    page.get_by_test_id("study-attitude_deg").fill("20")

    # the JSON view: the same spec; an edit there shows in the form
    page.get_by_test_id("study-view").click()
    spec = json.loads(page.get_by_test_id("study-spec").input_value())
    assert spec == {
        "name": "page",
        "seed": 1,
        "frames_per_cell": 3,
        "chunk_frames": 1,
        "grid": {"range_m": [2.5, 5], "attitude_deg": [20], "physics": ["ideal", "grey plate"]},
        "requirements": {"pitch_deg": 0.5},
    }
    page.get_by_test_id("study-spec").fill(json.dumps({**spec, "seed": 7}))
    page.get_by_test_id("study-view").click()
    assert page.get_by_test_id("study-seed").input_value() == "7"
    assert page.get_by_test_id("study-range_m-step").input_value() == "2.5"
    page.get_by_test_id("new-study").screenshot(path=str(SHOTS / "study-form.png"))

    page.get_by_test_id("study-submit").click()
    row = page.get_by_test_id("study-1")
    row.wait_for(timeout=5000)
    assert "12 (4 cells)" in row.inner_text()
    assert page.get_by_test_id("study-error-grid.attitude_deg").count() == 0
    page.wait_for_function(
        "document.querySelector('[data-testid=study-status-1]').innerText === 'complete'",
        timeout=240_000,
    )
    assert "12 / 12" in row.inner_text()
    page.set_viewport_size({"width": 1366, "height": 768})
    row.scroll_into_view_if_needed()
    page.screenshot(path=str(SHOTS / "studies.png"))
    href = page.get_by_test_id("study-report-html-1").get_attribute("href")
    assert href == "/api/studies/1/report.html"
    report = page.context.new_page()
    report.goto(server.base_url + href)
    assert "Accuracy study page" in report.inner_text("h1")
    verdict = report.get_by_test_id("study-verdict").inner_text()
    assert verdict.startswith(("PASS: all 4 cells meet", "FAIL: ")) and "pitch 0.5 deg" in verdict
    # the plots load (relative to the report) and are drawn
    report.wait_for_function(
        "[...document.images].length === 3 && [...document.images].every(i => i.naturalWidth > 0)",
        timeout=10_000,
    )
    assert report.locator("table").nth(0).locator("tr").count() == 5  # header + 4 cells
    report.screenshot(path=str(SHOTS / "study-report.png"), full_page=True)
