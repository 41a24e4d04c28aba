"""POST /api/motion/profile: a sine or a ramp on one rotary axis, checked against the soft,
rate and acceleration limits before anything moves, shown in GET /api/motion while it
runs, ended by STOP; the simulated table follows it (encoders against the profile at
their own time stamps)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from backend.drivers.factory import build_devices
from backend.drivers.scpi import ScpiRateTable
from backend.emulators.rate_table import RateTableEmulator
from tests.backend.conftest import AUTH, SpyMotion, make_settings, running_app, wait_for
from tofpose.lab.motion_profile import SineProfile

SINE = {"axis": "yaw", "kind": "sine", "amplitude_deg": 5.0, "period_s": 4.0, "cycles": 1}


@pytest.fixture
def fast_devices(tmp_path):
    """The simulated lab at 4x real time (a 12 s profile in 3 s), its table spied on."""
    settings = make_settings(tmp_path / "data", sim_time_scale=4.0)
    devs = build_devices(settings)
    devs.motion = SpyMotion(devs.motion)
    return settings, devs


def _profile_calls(spy: SpyMotion) -> list:
    return [call for call in spy.calls if call[0] == "run_profile"]


def test_the_simulated_table_follows_a_sine_slew(fast_devices):
    """The issue's slew (yaw, 5 deg, 4 s period): every encoder reading the API reports
    lies on the profile at the reading's time stamp, the rate from consecutive stamped
    readings follows the profile's rate, and the status says what runs and how long for."""
    settings, devs = fast_devices
    with running_app(settings, devs) as c:
        start = c.get("/api/motion").json()["positions"]["yaw"]
        r = c.post("/api/motion/profile", json=SINE, headers=AUTH)
        assert r.status_code == 202, r.text
        first = r.json()["profile"]
        assert first["axis"] == "yaw" and first["kind"] == "sine"
        assert first["duration_s"] == pytest.approx(12.0)
        reads = []
        while (m := c.get("/api/motion").json())["profile"] is not None:
            p = m["profile"]
            assert m["busy"] and p["elapsed_s"] + p["remaining_s"] == pytest.approx(12.0)
            reads.append((m["time_s"], m["positions"]["yaw"], p["elapsed_s"]))
            time.sleep(0.02)
        assert not c.get("/api/motion").json()["busy"]
    t_s, yaw, elapsed = (np.array(col) for col in zip(*reads, strict=True))
    assert len(reads) > 40 and elapsed.max() > 11.0 and np.all(np.diff(elapsed) > 0)
    t0 = t_s[0] - elapsed[0]
    profile = SineProfile(5.0, 4.0, 1, start_deg=start)
    assert np.abs(yaw - profile.angle_deg_at(t_s - t0)).max() < 2e-3
    # rates over reads >= 0.1 s apart: two reads a few ms apart (a loaded machine) turn
    # the angles' 2e-3 deg agreement into a rate error of whole deg/s
    keep = [0]
    for i in range(1, len(t_s)):
        if t_s[i] - t_s[keep[-1]] >= 0.1:
            keep.append(i)
    ts, ys = t_s[keep], yaw[keep]
    assert len(keep) > 60
    rate = np.diff(ys) / np.diff(ts)
    mid = 0.5 * (ts[1:] + ts[:-1]) - t0
    assert np.abs(rate - profile.rate_deg_s_at(mid)).max() < 0.15
    assert np.abs(rate).max() == pytest.approx(5.0 * 2 * np.pi / 4.0, rel=0.05)
    (call,) = _profile_calls(devs.motion)
    assert call[1]["axis"] == "yaw"
    assert call[1]["profile"].start_deg == pytest.approx(start, abs=2e-3)  # the encoder then


@pytest.mark.parametrize(
    ("body", "field", "needle"),
    [
        (
            {**SINE, "amplitude_deg": 10.0, "period_s": 2.0},
            "amplitude_deg",
            "exceeds the yaw rate limit of 20 deg/s",
        ),
        # 4 deg at 2 s: 39.5 deg/s^2 at full amplitude, 41.4 in the fades, limit 40
        (
            {**SINE, "amplitude_deg": 4.0, "period_s": 2.0},
            "period_s",
            "peak acceleration 41.4195 deg/s^2",
        ),
        (
            {"axis": "pitch", "kind": "ramp", "rate_deg_s": 10.0, "hold_s": 10.0},
            "hold_s",
            "beyond its soft limits [-60, 60] deg",
        ),
        (
            {
                "axis": "roll",
                "kind": "ramp",
                "rate_deg_s": -5.0,
                "hold_s": 1.0,
                "accel_deg_s2": 80.0,
            },
            "accel_deg_s2",
            "acceleration limit of 60",
        ),
        (
            {"axis": "roll", "kind": "ramp", "rate_deg_s": 31.0, "hold_s": 1.0},
            "rate_deg_s",
            "peak rate 31 deg/s",
        ),
    ],
)
def test_a_profile_beyond_a_limit_is_refused_and_the_table_does_not_move(
    settings, spy_devices, body, field, needle
):
    with running_app(settings, spy_devices) as c:
        before = c.get("/api/motion").json()
        r = c.post("/api/motion/profile", json=body, headers=AUTH)
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert ["body", field] in [d["loc"] for d in detail]
        assert any(needle in d["msg"] for d in detail), detail
        assert spy_devices.motion.calls == []  # nothing reached the driver
        time.sleep(0.2)
        after = c.get("/api/motion").json()
        assert not after["busy"] and after["profile"] is None
        assert after["targets"] == before["targets"]
        for axis, value in before["positions"].items():  # within encoder noise
            assert after["positions"][axis] == pytest.approx(
                value, abs=0.1 if axis == "rail" else 2e-3
            )


def test_stop_ends_a_running_profile_where_the_axis_is(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        ramp = {"axis": "roll", "kind": "ramp", "rate_deg_s": 10.0, "hold_s": 8.0}
        assert c.post("/api/motion/profile", json=ramp, headers=AUTH).status_code == 202
        wait_for(
            lambda: c.get("/api/motion").json()["positions"]["roll"] > 2.0,
            5.0,
            "the ramp to move the roll axis",
        )
        r = c.post("/api/motion/stop", headers=AUTH)
        assert r.status_code == 200
        stopped = r.json()
        assert stopped["profile"] is None and stopped["stopped"] and not stopped["busy"]
        time.sleep(0.3)
        later = c.get("/api/motion").json()
        assert later["profile"] is None
        assert later["positions"]["roll"] == pytest.approx(stopped["positions"]["roll"], abs=2e-3)
        assert later["positions"]["roll"] < 40.0  # it did not finish its 84 deg


def test_moves_of_the_profiled_axis_wait_for_stop(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        assert c.post("/api/motion/profile", json=SINE, headers=AUTH).status_code == 202
        r = c.post("/api/motion/move", json={"yaw_deg": 10.0}, headers=AUTH)
        assert r.status_code == 409 and "STOP it first" in r.json()["detail"], r.text
        r = c.post("/api/motion/jog", json={"yaw_deg": 1.0}, headers=AUTH)
        assert r.status_code == 409 and "still moving" in r.json()["detail"]
        r = c.post("/api/motion/profile", json={**SINE, "axis": "pitch"}, headers=AUTH)
        assert r.status_code == 409 and "still moving" in r.json()["detail"]
        # another axis may move meanwhile
        assert (
            c.post("/api/motion/move", json={"rail_mm": 12990.0}, headers=AUTH).status_code == 202
        )
        assert [name for name, _ in spy_devices.motion.calls] == ["run_profile", "move_to"]
        assert c.get("/api/motion").json()["profile"]["axis"] == "yaw"


def test_a_profile_needs_the_token(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            r = c.post("/api/motion/profile", json=SINE, headers=headers)
            assert r.status_code == 401
        assert spy_devices.motion.calls == []
        assert c.get("/api/motion").json()["profile"] is None


def test_a_controller_without_synthesis_mode_is_refused_with_409(tmp_path):
    settings = make_settings(tmp_path / "data")
    devs = build_devices(settings)
    with RateTableEmulator(devs.world, port=0, synthesis=False) as emu:
        devs.motion = ScpiRateTable(emu.resource, timeout_s=1.0)
        with running_app(settings, devs) as c:
            r = c.post("/api/motion/profile", json=SINE, headers=AUTH)
            assert r.status_code == 409, r.text
            assert "has no synthesis mode" in r.json()["detail"]
            assert "cannot run motion profiles" in r.json()["detail"]
            assert devs.world.bench.turntable.running_profile(devs.world.now_s()) is None


def test_the_scpi_table_runs_a_profile_through_the_api(tmp_path):
    """The emulated controller's synthesis mode, through the server: accepted, shown while
    it runs, and the axis swings on the simulated table behind the emulator."""
    settings = make_settings(tmp_path / "data")
    devs = build_devices(settings)
    with RateTableEmulator(devs.world, port=0) as emu:
        devs.motion = ScpiRateTable(emu.resource, timeout_s=1.0)
        with running_app(settings, devs) as c:
            axes = {a["name"]: a for a in c.get("/api/motion").json()["axes"]}
            assert axes["yaw"]["max_accel_per_s2"] == 40.0
            body = {**SINE, "amplitude_deg": 2.0, "period_s": 1.5}
            r = c.post("/api/motion/profile", json=body, headers=AUTH)
            assert r.status_code == 202, r.text
            assert r.json()["profile"]["kind"] == "sine"
            wait_for(
                lambda: abs(c.get("/api/motion").json()["positions"]["yaw"]) > 0.5,
                3.0,
                "the yaw axis to swing",
            )
            assert c.post("/api/motion/stop", headers=AUTH).json()["profile"] is None
