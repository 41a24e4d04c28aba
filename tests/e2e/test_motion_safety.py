"""No control of the dashboard sends a move the user did not type: an empty, partial or
out-of-limit go-to field sends nothing and says why; Enter and double clicks send one
move; a jog is a relative step the server applies; while the turntable's status is stale
or a campaign owns it, the controls are locked (and the camera panel's, while a campaign
runs). Every request the page makes is recorded and compared with what the user did."""

from __future__ import annotations

import json
import time

import httpx
import pytest
from playwright.sync_api import expect

from tests.backend.conftest import AUTH, TOKEN, LiveServer, make_settings, wait_for
from tests.e2e.conftest import SHOTS

MOVES = ("/api/motion/move", "/api/motion/jog")


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data", sim_time_scale=3.0)) as srv:
        yield srv


def _open(server, page_for):
    """The dashboard with a token, and the list of motion commands it sends."""
    page = page_for(server.base_url, TOKEN)
    sent: list[tuple[str, dict]] = []

    def record(request):
        path = "/" + request.url.split("/", 3)[3]
        if request.method == "POST" and path in MOVES:
            sent.append((path, json.loads(request.post_data or "null")))

    page.on("request", record)
    page.goto(server.base_url + "/")
    page.get_by_test_id("target-yaw").wait_for(timeout=20_000)
    page.get_by_test_id("pos-yaw").wait_for(timeout=20_000)
    return page, sent


def _enter_until_sent(page, axis: str, sent: list, tries: int = 5) -> None:
    """Press Enter in ``axis``'s go-to field until the page sends the move.

    The page refuses an Enter while the turntable's status is stale (no answer for 2 s,
    which two busy cores can cause): it then says "not sent: ..." under the field and
    sends nothing. Each refusal is checked to be that one, never a silent drop.
    """
    field = page.get_by_test_id(f"target-{axis}")
    for _ in range(tries):
        expect(page.get_by_test_id(f"go-{axis}")).to_be_enabled(timeout=15_000)
        field.press("Enter")
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline and not sent:
            err = page.get_by_test_id(f"target-error-{axis}")
            if err.count() and "not sent:" in err.inner_text():
                break
            page.wait_for_timeout(50)
        if sent:
            return
        err = page.get_by_test_id(f"target-error-{axis}")
        assert err.count() and "not sent: turntable status is stale" in err.inner_text(), (
            "Enter sent nothing and the page did not say why"
        )
        field.fill(field.input_value())  # typing clears the refusal, as a user's would
    pytest.fail(f"the page refused Enter {tries} times: its turntable status stayed stale")


def _motion(server) -> dict:
    return httpx.get(server.base_url + "/api/motion").json()


@pytest.mark.parametrize("typed", ["", "   ", "-", "1.", "1e", "abc", "1,5", "0x10", "--1"])
def test_a_field_that_is_not_a_number_sends_nothing_and_says_why(server, page_for, typed):
    page, sent = _open(server, page_for)
    page.get_by_test_id("target-yaw").fill(typed)
    page.get_by_test_id("go-yaw").click()
    err = page.get_by_test_id("target-error-yaw")
    err.wait_for(timeout=5000)
    text = err.inner_text()
    assert ("empty" in text) if typed.strip() == "" else ("not a number" in text), text
    assert page.get_by_test_id("target-yaw").get_attribute("aria-invalid") == "true"
    page.get_by_test_id("target-yaw").press("Enter")  # Enter takes the same check
    page.wait_for_timeout(800)
    assert sent == []
    assert _motion(server)["targets"].get("yaw", 0.0) == 0.0 and not _motion(server)["busy"]


def test_an_out_of_limit_target_is_refused_in_the_field(server, page_for):
    page, sent = _open(server, page_for)
    page.get_by_test_id("target-pitch").fill("75")
    page.get_by_test_id("target-pitch").press("Enter")
    err = page.get_by_test_id("target-error-pitch")
    err.wait_for(timeout=5000)
    assert "outside pitch's limits" in err.inner_text()
    page.wait_for_timeout(500)
    assert sent == []
    # typing again clears the message; a valid number then moves the axis, once
    page.get_by_test_id("target-pitch").fill("2.5")
    assert page.get_by_test_id("target-error-pitch").count() == 0
    # on a loaded machine the status can go stale for a moment (locked: Enter is refused
    # in the field with "not sent: ..."): the user presses Enter again once the controls
    # are usable, as often as the page refuses it
    _enter_until_sent(page, "pitch", sent)
    page.wait_for_timeout(500)
    assert sent == [("/api/motion/move", {"pitch_deg": 2.5})]
    wait_for(lambda: abs(_motion(server)["positions"]["pitch"] - 2.5) < 0.01, 20.0, "pitch 2.5")


def test_a_double_click_on_go_sends_one_move(server, page_for):
    page, sent = _open(server, page_for)
    page.get_by_test_id("target-roll").fill("-3")
    page.get_by_test_id("go-roll").dblclick()
    page.wait_for_timeout(1000)
    assert sent == [("/api/motion/move", {"roll_deg": -3.0})]


def test_a_jog_is_a_relative_step_the_server_applies(server, page_for):
    page, sent = _open(server, page_for)
    r = httpx.post(server.base_url + "/api/motion/move", json={"yaw_deg": 6.0}, headers=AUTH)
    assert r.status_code == 202
    wait_for(
        lambda: (m := _motion(server))["settled"] and abs(m["positions"]["yaw"] - 6) < 0.01,
        20.0,
        "yaw at 6 deg",
    )
    page.get_by_test_id("jog-yaw-plus").dblclick()  # one jog: the second click waits
    wait_for(lambda: sent, 5.0, "the jog request")
    page.wait_for_timeout(800)
    assert sent == [("/api/motion/jog", {"yaw_deg": 1})]
    wait_for(
        lambda: (m := _motion(server))["settled"] and abs(m["positions"]["yaw"] - 7) < 0.02,
        20.0,
        "yaw at 7 deg",
    )


def test_controls_lock_while_the_turntable_status_is_stale(server, page_for):
    page, sent = _open(server, page_for)
    page.get_by_test_id("target-yaw").fill("5")
    # the motion status stops answering (a dropped link): the view goes stale
    page.context.route("**/api/motion", lambda route: route.abort())
    page.get_by_test_id("motion-locked").wait_for(timeout=6000)
    assert "stale" in page.get_by_test_id("motion-locked").inner_text()
    assert page.get_by_test_id("go-yaw").is_disabled()
    assert page.get_by_test_id("jog-yaw-plus").is_disabled()
    page.get_by_test_id("target-yaw").press("Enter")
    # Enter on a locked field says why nothing was sent
    refused = page.get_by_test_id("target-error-yaw")
    refused.wait_for(timeout=5000)
    assert "not sent" in refused.inner_text() and "stale" in refused.inner_text()
    panel = page.get_by_test_id("motion-locked").locator("xpath=..")  # the turntable card
    panel.screenshot(path=str(SHOTS / "motion-enter-while-locked.png"))
    page.get_by_test_id("go-yaw").click(force=True)
    page.get_by_test_id("jog-yaw-plus").click(force=True)
    page.wait_for_timeout(800)
    assert sent == []
    assert page.get_by_test_id("stop").is_enabled()  # STOP is never locked
    page.context.unroute("**/api/motion")
    wait_for(lambda: page.get_by_test_id("motion-locked").count() == 0, 6.0, "the lock to lift")
    assert page.get_by_test_id("go-yaw").is_enabled()


def test_controls_lock_while_a_campaign_owns_the_turntable(server, page_for):
    page, sent = _open(server, page_for)
    body = {
        "name": "owner",
        "frames_per_point": 400,
        "settle_s": 0.5,
        "setpoints": [{"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 11000}],
    }
    cid = httpx.post(server.base_url + "/api/campaigns", json=body, headers=AUTH).json()["id"]
    assert (
        httpx.post(f"{server.base_url}/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
    )
    locked = page.get_by_test_id("motion-locked")
    locked.wait_for(timeout=10_000)
    assert f"campaign {cid}" in locked.inner_text() and "owns the turntable" in locked.inner_text()
    # the camera too: the campaign sets it per set-point, so its panel is locked and says so
    cam_locked = page.get_by_test_id("cam-locked")
    cam_locked.wait_for(timeout=10_000)
    assert f"campaign {cid} ('owner')" in cam_locked.inner_text()
    assert page.get_by_test_id("cam-apply").is_disabled()
    assert page.get_by_test_id("cam-integration_time_us").is_disabled()
    page.get_by_test_id("target-rail").fill("12000")
    assert page.get_by_test_id("go-rail").is_disabled()
    assert page.get_by_test_id("jog-rail-minus").is_disabled()
    page.get_by_test_id("target-rail").press("Enter")
    page.get_by_test_id("jog-rail-minus").click(force=True)
    page.wait_for_timeout(800)
    page.screenshot(path=str(SHOTS / "dashboard-motion-locked.png"), full_page=False)
    assert sent == []
    httpx.post(f"{server.base_url}/api/campaigns/{cid}/cancel", headers=AUTH)
    wait_for(lambda: locked.count() == 0, 6.0, "the lock to lift after the cancel")
    wait_for(lambda: cam_locked.count() == 0, 6.0, "the camera's lock to lift")
    assert page.get_by_test_id("cam-apply").is_enabled()


def test_stop_latches_in_the_page_until_a_person_releases_it(server, page_for):
    """STOP (here: Esc) latches on the server: the panel says so, go-to and jog are locked
    and send nothing, "release STOP" lets moves through again; the audit trail (admin
    key) lists the STOP and the release under the key's name."""
    page, sent = _open(server, page_for)
    page.keyboard.press("Escape")
    banner = page.get_by_test_id("stop-latched")
    banner.wait_for(timeout=6000)
    assert "STOP latched" in banner.inner_text()
    assert "holds the turntable" in page.get_by_test_id("motion-locked").inner_text()
    assert _motion(server)["stop_latched"] is True
    page.get_by_test_id("target-yaw").fill("5")
    assert page.get_by_test_id("go-yaw").is_disabled()
    page.get_by_test_id("target-yaw").press("Enter")
    page.get_by_test_id("jog-yaw-plus").click(force=True)
    page.wait_for_timeout(800)
    assert sent == []
    page.screenshot(path=str(SHOTS / "motion-stop-latched.png"), full_page=False)
    page.get_by_test_id("release-stop").click()
    wait_for(lambda: page.get_by_test_id("stop-latched").count() == 0, 6.0, "the latch to go")
    assert _motion(server)["stop_latched"] is False
    # a click the panel refused (under load a poll older than 2 s locks the controls, and
    # the field says "not sent": a person clicks again) is clicked again, only while
    # nothing has been sent 3 s after it, so the one move below is the only one
    deadline = time.monotonic() + 15.0
    while not sent and time.monotonic() < deadline:
        expect(page.get_by_test_id("go-yaw")).to_be_enabled(timeout=15_000)
        page.get_by_test_id("go-yaw").click()
        until = time.monotonic() + 3.0  # a click that is taken sends at once
        while not sent and time.monotonic() < until:
            page.wait_for_timeout(100)
    assert sent == [("/api/motion/move", {"yaw_deg": 5.0})], sent
    # the audit lists a request once the server has answered it
    wait_for(lambda: _motion(server)["targets"].get("yaw") == 5.0, 15.0, "the move's answer")
    page.get_by_test_id("audit-toggle").click()
    audit = page.get_by_test_id("audit")
    audit.wait_for(timeout=6000)
    text = audit.inner_text()
    for path in ("/api/motion/stop", "/api/motion/release", "/api/motion/move"):
        assert path in text, text
    assert "admin" in text  # the bootstrap key's name
