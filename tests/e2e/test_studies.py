"""Accuracy studies in the dashboard: a spec typed into the page is refused with the
field named when it cannot run, runs when it can, shows its progress to complete, and
its report opens (plots included)."""

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


def test_a_study_submitted_in_the_page_runs_and_its_report_opens(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_text("new study").click()
    spec = page.get_by_test_id("study-spec")
    bad = {
        "name": "page",
        "frames_per_cell": 3,
        "chunk_frames": 1,
        "grid": {"range_m": [2.5, 2.5], "physics": ["ideal", "grey plate"]},
    }
    spec.fill(json.dumps(bad))
    page.get_by_test_id("study-submit").click()
    err = page.get_by_test_id("error")
    err.wait_for(timeout=5000)
    assert "422" in err.inner_text() and "grid.range_m" in err.inner_text()
    spec.fill(json.dumps({**bad, "grid": {**bad["grid"], "range_m": [2.5, 5.0]}}))
    page.get_by_test_id("study-submit").click()
    row = page.get_by_test_id("study-1")
    row.wait_for(timeout=5000)
    assert "12 (4 cells)" in row.inner_text()
    page.wait_for_function(
        "document.querySelector('[data-testid=study-status-1]').innerText === 'complete'",
        timeout=240_000,
    )
    assert "12 / 12" in row.inner_text()
    row.scroll_into_view_if_needed()
    page.get_by_test_id("studies").screenshot(path=str(SHOTS / "studies.png"))
    href = page.get_by_test_id("study-report-html-1").get_attribute("href")
    assert href == "/api/studies/1/report.html"
    report = page.context.new_page()
    report.goto(server.base_url + href)
    assert "Accuracy study page" in report.inner_text("h1")
    # the plots load (relative to the report) and are drawn
    report.wait_for_function(
        "[...document.images].length === 3 && [...document.images].every(i => i.naturalWidth > 0)",
        timeout=10_000,
    )
    assert report.locator("table tr").count() == 5  # header + 4 cells
    report.screenshot(path=str(SHOTS / "study-report.png"), full_page=True)
