"""POST /api/motion/jog: a relative move the server applies to the axis' encoder
position when the request arrives, refused while the axis moves or when it would leave
the soft limits; nothing refused reaches the driver (nor does a malformed profile:
tests/backend/api/test_motion_profile.py has the rest of those)."""

from __future__ import annotations

import pytest

from tests.backend.conftest import AUTH, running_app, wait_for


def _settled(c) -> dict:
    return wait_for(
        lambda: (m := c.get("/api/motion").json())["settled"] and m,
        20.0,
        "the motion system to settle",
    )


def test_a_jog_moves_from_the_encoder_position_not_from_a_stale_view(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        assert c.post("/api/motion/move", json={"yaw_deg": 4.0}, headers=AUTH).status_code == 202
        before = _settled(c)["positions"]["yaw"]
        assert abs(before - 4.0) < 0.01
        spy_devices.motion.calls.clear()
        # the client last saw yaw = 0 (stale): the step is still applied to 4 deg
        r = c.post("/api/motion/jog", json={"yaw_deg": -1.0}, headers=AUTH)
        assert r.status_code == 202, r.text
        (call,) = spy_devices.motion.calls
        assert call[0] == "move_to" and set(call[1]) == {"yaw"}
        # from the encoder reading when the jog arrived (it jitters by < 0.01 deg when
        # settled), not from the target or from 0
        assert call[1]["yaw"] == pytest.approx(before - 1.0, abs=0.01)
        assert abs(_settled(c)["positions"]["yaw"] - 3.0) < 0.01


def test_after_a_stop_a_jog_starts_where_the_axis_stopped_not_at_its_target(settings, spy_devices):
    """STOP mid-move leaves the target (170 deg) far from the encoder: the jog's step is
    added to the encoder reading."""
    with running_app(settings, spy_devices) as c:
        assert c.post("/api/motion/move", json={"roll_deg": 170.0}, headers=AUTH).status_code == 202
        wait_for(
            lambda: c.get("/api/motion").json()["positions"]["roll"] > 5.0,
            10.0,
            "the roll axis to move",
        )
        assert c.post("/api/motion/stop", headers=AUTH).status_code == 200
        wait_for(lambda: not c.get("/api/motion").json()["busy"], 5.0, "the stop")
        stopped_at = c.get("/api/motion").json()["positions"]["roll"]
        assert stopped_at < 100.0
        spy_devices.motion.calls.clear()
        r = c.post("/api/motion/jog", json={"roll_deg": 1.0}, headers=AUTH)
        assert r.status_code == 409 and "release it first" in r.json()["detail"]  # latched
        released = c.post("/api/motion/release", headers=AUTH)
        assert released.status_code == 200 and released.json()["stop_latched"] is False
        r = c.post("/api/motion/jog", json={"roll_deg": 1.0}, headers=AUTH)
        assert r.status_code == 202, r.text
        ((name, setpoint),) = spy_devices.motion.calls
        assert name == "move_to" and setpoint["roll"] == pytest.approx(stopped_at + 1.0, abs=0.05)


def test_a_second_jog_while_moving_is_refused(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        _settled(c)
        assert c.post("/api/motion/jog", json={"rail_mm": 1000.0}, headers=AUTH).status_code == 202
        wait_for(lambda: c.get("/api/motion").json()["busy"], 2.0, "the move to start")
        r = c.post("/api/motion/jog", json={"rail_mm": 1000.0}, headers=AUTH)
        assert r.status_code == 409 and "still moving" in r.json()["detail"]
        assert [name for name, _ in spy_devices.motion.calls] == ["move_to"]


SINE = {"axis": "yaw", "kind": "sine", "amplitude_deg": 5.0, "period_s": 4.0, "cycles": 1}
RAMP = {"axis": "yaw", "kind": "ramp", "rate_deg_s": 3.0, "hold_s": 1.0}


@pytest.mark.parametrize(
    ("path", "body", "needle"),
    [
        ("jog", {"yaw_deg": 0}, "moves nothing"),
        ("jog", {"yaw_deg": 11}, "less than or equal to 10"),
        ("jog", {"rail_mm": -1001}, "greater than or equal to -1000"),
        ("jog", {"tilt_deg": 1}, "extra"),
        ("jog", {}, "at least one"),
        ("jog", {"yaw_deg": 1, "rail_mm": 10}, "exactly one"),
        ("jog", {"yaw_deg": "1"}, "yaw_deg"),
        ("jog", {"yaw_deg": None}, "null is not a set-point"),
        ("jog", {"pitch_deg": -1, "rail_mm": None}, "null is not a set-point"),
        ("profile", {**SINE, "rate_deg_s": 3.0}, "Extra inputs"),
        ("profile", {**RAMP, "cycles": 2}, "Extra inputs"),
        ("profile", {**RAMP, "rate_deg_s": 0}, "moves nothing"),
        ("profile", {**RAMP, "accel_deg_s2": None}, "null is not an acceleration"),
        ("profile", {**SINE, "axis": "rail"}, "'yaw', 'pitch' or 'roll'"),
        ("profile", {**SINE, "kind": "square"}, "'sine', 'ramp'"),
        ("profile", {**SINE, "cycles": 0}, "greater than or equal to 1"),
        ("profile", {**SINE, "period_s": "4"}, "period_s"),
    ],
)
def test_bad_jogs_and_profiles_are_refused_with_a_reason(settings, spy_devices, path, body, needle):
    with running_app(settings, spy_devices) as c:
        r = c.post(f"/api/motion/{path}", json=body, headers=AUTH)
        assert r.status_code == 422, r.text
        assert needle in str(r.json()["detail"]), r.text
        assert spy_devices.motion.calls == []


def test_a_jog_past_the_soft_limit_is_refused(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        limit = next(a for a in c.get("/api/motion").json()["axes"] if a["name"] == "pitch")
        assert (
            c.post(
                "/api/motion/move", json={"pitch_deg": limit["max_pos"] - 0.5}, headers=AUTH
            ).status_code
            == 202
        )
        _settled(c)
        spy_devices.motion.calls.clear()
        r = c.post("/api/motion/jog", json={"pitch_deg": 1.0}, headers=AUTH)
        assert r.status_code == 422 and "soft limits" in str(r.json()["detail"]), r.text
        assert spy_devices.motion.calls == []


def test_jog_needs_the_token(client):
    for headers in ({}, {"Authorization": "Bearer wrong"}):
        r = client.post("/api/motion/jog", json={"yaw_deg": 1}, headers=headers)
        assert r.status_code == 401
