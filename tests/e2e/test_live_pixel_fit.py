"""The pixel-level fit in the live view (``TOFPOSE_PIXEL_FIT``): the pose panel says the
pose and sigmas shown are the fit's, with its time, and the sigmas it shows are the
pose message's (narrower than the centroid pose's at 3 m: ``tests/backend/api/
test_pose_pixel_fit.py``)."""

from __future__ import annotations

import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS, live_page_with_matches


@pytest.fixture
def server(tmp_path):
    settings = make_settings(tmp_path / "data", pixel_fit=True, sim_start_rail_mm=12000.0)
    with LiveServer(settings) as srv:
        yield srv


def test_the_pose_panel_says_the_pose_is_the_pixel_fits(server, page_for):
    page = live_page_with_matches(page_for, server.base_url, TOKEN)
    line = page.get_by_test_id("pose-pixel-fit")
    page.wait_for_function(
        "(document.querySelector('[data-testid=pose-pixel-fit]')?.textContent || '')"
        ".startsWith('refined on the markers')",
        timeout=60_000,
    )
    assert "the pose and sigmas of the sensor model's fit" in line.inner_text()
    assert " ms)" in line.inner_text()
    # the panel's z reads the lab's 3 m
    z_mm = float(page.get_by_test_id("pose-z").inner_text())
    assert z_mm == pytest.approx(3000.0, abs=150.0)
    line.locator("xpath=ancestor::section[1]").screenshot(path=str(SHOTS / "pose-pixel-fit.png"))
