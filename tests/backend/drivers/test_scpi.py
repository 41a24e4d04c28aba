"""The SCPI rate-table driver (PyVISA, pyvisa-py) against the shipped emulator: moves,
read-back, refusals with interlocks open or faults, stop that never waits, link loss."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from backend.drivers.base import MotionError
from backend.drivers.scpi import ScpiRateTable
from backend.drivers.sim import make_sim_world
from backend.emulators.rate_table import RateTableEmulator
from tests.backend.conftest import wait_for
from tofpose.lab.motion_profile import RampProfile, SineProfile


@pytest.fixture
def emu():
    with RateTableEmulator(make_sim_world(time_scale=20.0), port=0) as e:
        yield e


@pytest.fixture
def table(emu):
    drv = ScpiRateTable(emu.resource, timeout_s=1.0)
    yield drv
    drv.close()


def test_axes_and_limits_come_from_the_controller(emu):
    emu.controller.axes[1].low = -30.0  # the controller's limits, not ours
    drv = ScpiRateTable(emu.resource, axis_numbers={"yaw": 1, "pitch": 2, "extra": 7})
    try:
        assert set(drv.axes) == {"yaw", "pitch"}  # axis 7 does not exist: left out
        assert drv.axes["yaw"].min_pos == -30.0 and drv.axes["yaw"].max_pos == 170.0
        assert drv.axes["yaw"].unit == "deg" and drv.axes["yaw"].max_rate == 20.0
        info = drv.describe()
        assert "ACUTROL3000" in info["model"] and info["link"] == "up"
    finally:
        drv.close()


def test_moves_and_reports_encoder_positions(emu, table):
    table.move_to({"yaw": 12.5, "pitch": -4.0, "rail": 12000.0})
    st = wait_for(lambda: (s := table.status()).settled and s, 10.0, "the move to settle")
    assert st.positions["yaw"] == pytest.approx(12.5, abs=1e-3)
    assert st.positions["pitch"] == pytest.approx(-4.0, abs=1e-3)
    assert st.positions["rail"] == pytest.approx(12000.0, abs=0.1)
    assert st.targets["yaw"] == pytest.approx(12.5) and not st.busy
    truth = emu.controller.world.bench.turntable.target_position()
    assert truth["yaw"] == pytest.approx(12.5)  # the simulated table did move there


def test_refuses_with_safety_interlock_open_until_closed(emu, table):
    emu.controller.set_safety_open(True)
    with pytest.raises(MotionError, match="Safety interlock open"):
        table.move_to({"yaw": 5.0})
    assert emu.controller.world.bench.turntable.target_position()["yaw"] == 0.0
    emu.controller.set_safety_open(False)
    table.move_to({"yaw": 5.0})  # the driver closes the axis interlock again itself
    wait_for(lambda: table.status().positions["yaw"] > 4.99, 10.0, "the move after closing")


def test_recovers_from_an_injected_fault(emu, table):
    table.move_to({"roll": 40.0})
    emu.controller.inject_fault(3, "amplifier overtemperature")
    assert table.status().stopped
    with pytest.raises(MotionError, match="203 Axis fault; amplifier overtemperature"):
        table.move_to({"roll": 0.0})
    table.reset_faults()
    table.move_to({"roll": 0.0})
    wait_for(lambda: (s := table.status()).settled and abs(s.positions["roll"]) < 1e-3, 10.0)


def test_out_of_limit_set_point_names_the_controller_error(table):
    with pytest.raises(MotionError, match=r"-222 Data out of range; 200 outside \[-60, 60\]"):
        table.move_to({"pitch": 200.0})


def test_stop_goes_out_while_the_command_session_is_busy(emu, table):
    table.move_to({"yaw": 150.0})
    time.sleep(0.05)
    with table._lock:  # a status query or move hangs on the command session
        t0 = time.monotonic()
        table.stop()  # must not wait for that session
        took = time.monotonic() - t0
    assert took < 1.0
    st = table.status()
    assert st.stopped and 0 < st.positions["yaw"] < 150.0


def test_link_drop_raises_then_reconnects(emu, table):
    host, port = emu.address
    world = emu.controller.world
    emu.close()
    with pytest.raises(MotionError, match="no answer"):
        table.status()
    assert table.describe()["link"] == "down"
    with RateTableEmulator(world, host, port):  # the controller is back
        st = table.status()
        assert "yaw" in st.positions and table.describe()["link"] == "up"


def test_concurrent_status_and_moves_do_not_interleave_replies(table):
    errors = []

    def poll():
        try:
            for _ in range(30):
                assert len(table.status().positions) == 4
        except Exception as exc:  # noqa: BLE001 - collected for the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=poll) for _ in range(3)]
    for t in threads:
        t.start()
    for v in (1.0, 2.0, 3.0):
        table.move_to({"yaw": v})
    for t in threads:
        t.join()
    assert errors == []


def test_runs_a_sine_profile_through_synthesis_mode(emu, table):
    """The controller times the profile: the encoders read back through the driver follow
    the sine about the start, the status names it while it runs, and a move afterwards
    puts the axis back in position mode."""
    assert table.profile_unavailable is None and table.axes["yaw"].max_accel == 40.0
    table.move_to({"yaw": 20.0})
    wait_for(lambda: (s := table.status()).settled and s, 10.0, "the move to settle")
    profile = SineProfile(5.0, 4.0, 2)  # 16 lab-s, 0.8 s here
    table.run_profile("yaw", profile)
    started = profile.started_at(20.0)
    seen = []
    while (st := table.status()).profile is not None:
        assert st.profile.axis == "yaw" and st.profile.kind == "sine" and st.busy
        assert st.profile.duration_s == pytest.approx(16.0)
        seen.append((st.profile.elapsed_s, st.positions["yaw"]))
        time.sleep(0.01)
    assert len(seen) > 10 and max(y for _, y in seen) > 23.0  # swung out, not just sat
    for elapsed, yaw in seen:
        # the encoder and the elapsed time are answered a moment apart in one round trip
        # (20x lab time): the reading lies on the profile within 0.3 lab-s of it
        near = started.angle_deg_at(elapsed + np.linspace(-0.3, 0.3, 6001))
        assert np.abs(near - yaw).min() < 2e-3, (elapsed, yaw)
    assert emu.controller.axes[1].mode == "SYNT"
    assert table.status().positions["yaw"] == pytest.approx(20.0, abs=1e-3)
    table.move_to({"yaw": 0.0})
    wait_for(lambda: abs(table.status().positions["yaw"]) < 1e-3, 10.0, "the move back")
    assert emu.controller.axes[1].mode == "POS"


def test_stop_ends_a_profile_on_the_controller(emu, table):
    table.run_profile("roll", RampProfile(10.0, 10.0, 30.0))  # 103 deg in 10.7 lab-s
    time.sleep(0.1)
    table.stop()
    st = table.status()
    assert st.stopped and st.profile is None and not st.busy
    time.sleep(0.1)
    assert table.status().positions["roll"] == pytest.approx(st.positions["roll"], abs=1e-3)
    assert 1.0 < st.positions["roll"] < 100.0


def test_the_controllers_own_limit_check_is_reported(emu, table):
    emu.controller.axes[2].high = 3.0  # narrowed on the controller after the driver read it
    with pytest.raises(MotionError, match=r"-222 Data out of range; pitch would sweep"):
        table.run_profile("pitch", SineProfile(5.0, 4.0, 1))
    assert table.status().profile is None


def test_a_controller_without_synthesis_mode_refuses_profiles_clearly():
    with RateTableEmulator(make_sim_world(time_scale=20.0), port=0, synthesis=False) as emu:
        drv = ScpiRateTable(emu.resource, timeout_s=1.0)
        try:
            assert "has no synthesis mode" in drv.profile_unavailable
            with pytest.raises(MotionError, match="cannot run motion profiles"):
                drv.run_profile("yaw", SineProfile(5.0, 4.0, 1))
            st = drv.status()  # status still works, without the synthesis queries
            assert st.profile is None and not st.busy
            assert emu.controller.world.bench.turntable.running_profile(1e9) is None
            drv.move_to({"yaw": 1.0})  # and so do moves
            wait_for(lambda: drv.status().positions["yaw"] > 0.99, 10.0, "the move")
        finally:
            drv.close()
