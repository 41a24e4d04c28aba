"""The dashboard's 3-D panel at 1366 x 768 shows the ground grid, the rulers in metres
and the target's trail, and the scene's "Clear trail" button empties the trail."""

from __future__ import annotations

import re

import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings, wait_for
from tests.e2e.conftest import SHOTS

MATCHED = re.compile(r"frame \d+: \d+ matched")  # the status line of a drawn pose


@pytest.fixture
def server(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=3.0, viser=True, viser_port=0)
    with LiveServer(settings) as srv:
        yield srv


def test_the_dashboards_scene_has_grid_rulers_and_a_trail_that_clears(server, page_for):
    scene = server.server.config.app.state.tofpose.scene
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    frame_el = page.get_by_test_id("scene-frame")
    frame_el.wait_for(timeout=20_000)
    frame_el.scroll_into_view_if_needed()
    inner = page.frame_locator("[data-testid=scene-frame]")
    # the server's scene first (a pose drawn), then the browser's copy of it: viser's
    # client on software WebGL can take tens of seconds on a loaded machine
    wait_for(lambda: MATCHED.search(scene.status.content), 60.0, "a pose in the scene")
    inner.get_by_text(MATCHED).wait_for(timeout=60_000)
    wait_for(lambda: len(scene.trail) >= 10, 60.0, "10 poses on the trail")
    toast_close = inner.locator(".mantine-Notification-closeButton")
    if toast_close.count():
        toast_close.first.click()  # viser's note about software WebGL
    page.wait_for_timeout(1500)
    page.locator("section.scene").screenshot(path=str(SHOTS / "scene-ground.png"))
    page.screenshot(path=str(SHOTS / "scene-ground-page.png"))
    port = scene.port  # the scene on its own port, full size
    own = page_for(f"http://127.0.0.1:{port}")
    own.goto(f"http://127.0.0.1:{port}/")
    own.get_by_text(MATCHED).wait_for(timeout=60_000)
    own.wait_for_timeout(2000)
    own.screenshot(path=str(SHOTS / "scene-ground-own-tab.png"))
    # paused, the trail stops growing: the button must empty it
    page.get_by_test_id("scene-pause").check()
    wait_for(lambda: scene.paused, 10.0, "the scene to pause")
    assert len(scene.trail) >= 10
    inner.get_by_role("button", name="Clear trail").click()
    wait_for(lambda: len(scene.trail) == 0, 10.0, "the trail to be cleared")
    assert not scene.trail_node.visible
    page.get_by_test_id("scene-pause").uncheck()
    wait_for(lambda: len(scene.trail) >= 2, 20.0, "the trail to grow again")
