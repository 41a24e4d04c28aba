"""Distances beyond the unambiguous range in the live view (issue 49): the simulated lab
at 7 m, measured at the default 6 MHz (25 m unambiguous) as measured; the modulation set
to 24 MHz in the camera panel (6.25 m), the distances wrap and the pose is read one range
further: a line above the images says about which range, and the pose panel still reads
7 m."""

from __future__ import annotations

import re

import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings, wait_for
from tests.e2e.conftest import SHOTS, live_page_with_matches

NOTICE = re.compile(r"^distances read about (\d+\.\d) m: the target is beyond the range")


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data", sim_start_rail_mm=8000.0)) as srv:
        yield srv


def test_a_target_beyond_the_unambiguous_range_is_read_further_and_the_page_says_so(
    server, page_for
):
    page = live_page_with_matches(page_for, server.base_url, TOKEN)
    assert page.get_by_test_id("wrap-notice").count() == 0

    page.get_by_test_id("cam-modulation_frequency_mhz").fill("24")
    page.get_by_test_id("cam-apply").click()
    notice = page.get_by_test_id("wrap-notice")
    notice.wait_for(timeout=60_000)
    match = NOTICE.match(notice.inner_text())
    assert match, notice.inner_text()
    assert float(match.group(1)) == pytest.approx(7.0, abs=0.3)
    # the server's pose agrees: the lab's 7 m, not the wrapped 0.75 m
    pose = wait_for(
        lambda: (p := page.request.get(server.base_url + "/api/pose/latest").json())["ok"] and p,
        30.0,
        "an ok pose",
    )
    assert pose["z_mm"] == pytest.approx(7000.0, abs=300.0), pose
    notice.scroll_into_view_if_needed()
    page.screenshot(path=str(SHOTS / "live-wrap.png"), full_page=False)
