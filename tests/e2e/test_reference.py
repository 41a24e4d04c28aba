"""The dashboard says which lab reference its live error is measured against: the
nominal geometry is marked uncalibrated with the calibration campaign one click away,
and a stored calibration can be selected there."""

from __future__ import annotations

import httpx
import pytest
from playwright.sync_api import expect

from backend.db.models import CalibrationRow
from backend.services.live.live_reference import NOMINAL_LABEL
from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data")) as srv:
        yield srv


def test_the_reference_is_named_and_a_calibration_can_be_set_up_or_selected(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    label = page.get_by_test_id("reference-label")
    label.wait_for(timeout=20_000)
    assert label.inner_text() == NOMINAL_LABEL
    assert "mount and placement errors" in page.get_by_test_id("reference-warning").inner_text()
    # the pose panel names the lab's estimate "reference", never "truth" (only the pose a
    # simulator rendered is called truth: docs/interop.md, "Names: truth and reference")
    shown = page.get_by_test_id("pose-reference")
    shown.wait_for(timeout=20_000)
    text = shown.inner_text()
    assert text.startswith(f"lab reference, {NOMINAL_LABEL}:") and "error vs reference" in text
    assert float(page.get_by_test_id("pose-reference-error-mm").inner_text()) > 0.0
    panel = page.locator("section.card", has=page.get_by_test_id("pose")).inner_text()
    assert "truth" not in panel.lower(), panel
    page.screenshot(path=str(SHOTS / "dashboard-reference.png"), full_page=False)
    shown.screenshot(path=str(SHOTS / "pose-panel-reference.png"))
    # one click fills the new-campaign form with the calibration generator
    page.get_by_test_id("reference-calibrate").click()
    # the form fills in an effect after the click's render: wait for it, as a person would
    expect(page.get_by_test_id("new-kind")).to_have_value("calibration", timeout=10_000)
    expect(page.get_by_test_id("new-name")).to_have_value("bench-calibration", timeout=10_000)
    assert page.get_by_test_id("new-rails_mm").get_attribute("placeholder") == "11000, 12500"
    # a stored calibration appears in the selector; selecting it switches the reference
    state = server.server.config.app.state.tofpose
    g = state.devices.world.bench.geometry
    with state.sessions() as s, s.begin():
        row = CalibrationRow(
            name="bench-1",
            mount=g.T_inner_camera.compose(g.mount_error).as_matrix().tolist(),
            placement=g.T_lab_target.compose(g.placement_error).as_matrix().tolist(),
            sigmas=[0.0] * 12,
            residual_mm=[0.0],
            residual_deg=[0.0],
            chi2_per_dof=1.0,
            n_observations=0,
        )
        s.add(row)
        s.flush()
        cid = row.id
    select = page.get_by_test_id("reference-select")
    select.wait_for(timeout=10_000)
    select.select_option(str(cid))
    page.wait_for_function(
        f"document.querySelector('[data-testid=reference-label]').innerText"
        f" === \"calibration {cid} ('bench-1')\"",
        timeout=10_000,
    )
    assert page.get_by_test_id("reference-warning").count() == 0
    assert httpx.get(server.base_url + "/api/reference").json()["calibration_id"] == cid
    page.wait_for_function(
        "document.querySelector('[data-testid=pose-reference]').innerText.includes('bench-1')",
        timeout=10_000,
    )
