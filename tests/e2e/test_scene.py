"""The viser 3-D scene in a real browser: on its own port, and embedded in the dashboard;
its status follows the live pose, and the dashboard's pause control freezes it."""

from __future__ import annotations

import json
import re
import urllib.request

import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS


@pytest.fixture
def server(tmp_path):
    settings = make_settings(tmp_path / "data", sim_time_scale=3.0, viser=True, viser_port=0)
    with LiveServer(settings) as srv:
        yield srv


def _scene(server) -> dict:
    with urllib.request.urlopen(server.base_url + "/api/scene", timeout=5) as r:
        return json.load(r)


def _status_frame(text: str) -> int:
    m = re.search(r"frame (\d+): (\d+) matched", text)
    assert m, f"no pose status in the scene's panel: {text[:300]!r}"
    return int(m.group(1))


def test_the_scene_page_shows_the_live_pose_on_its_own_port(server, page_for):
    port = _scene(server)["port"]
    page = page_for(f"http://127.0.0.1:{port}")
    page.goto(f"http://127.0.0.1:{port}/")
    status = page.get_by_text(re.compile(r"frame \d+: 8 matched"))
    status.wait_for(timeout=30_000)
    assert page.get_by_text("Pause scene").is_visible()
    assert page.locator("canvas").count() >= 1
    first = _status_frame(status.inner_text())
    page.wait_for_function(
        f"""() => {{ const m = document.body.innerText.match(/frame (\\d+): \\d+ matched/);
                    return m && parseInt(m[1]) > {first}; }}""",
        timeout=15_000,
    )  # the scene updates live in the browser
    page.wait_for_timeout(2000)  # let the point cloud arrive and the renderer settle
    # viser's own toast about software WebGL (this headless browser has no GPU) would
    # cover part of the screenshot: dismiss it where it shows.
    toast_close = page.locator(".mantine-Notification-closeButton")
    if toast_close.count():
        toast_close.first.click()
    page.screenshot(path=str(SHOTS / "scene-3d.png"))


def test_the_dashboard_embeds_the_scene_and_pauses_it(server, page_for):
    port = _scene(server)["port"]
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    frame_el = page.get_by_test_id("scene-frame")
    frame_el.wait_for(timeout=20_000)
    assert frame_el.get_attribute("src") == f"http://127.0.0.1:{port}/"
    frame_el.scroll_into_view_if_needed()
    inner = page.frame_locator("[data-testid=scene-frame]")
    inner.get_by_text(re.compile(r"frame \d+: \d+ matched")).wait_for(timeout=30_000)
    page.get_by_test_id("scene-pause").check()
    page.wait_for_function("document.querySelector('[data-testid=scene-pause]').checked")
    assert _scene(server)["paused"] is True
    frozen = _scene(server)["updates"]
    page.wait_for_timeout(1500)
    assert _scene(server)["updates"] <= frozen + 1
    page.get_by_test_id("scene-pause").uncheck()
    page.wait_for_timeout(1500)
    assert _scene(server)["updates"] > frozen + 2
