"""Simulated camera + turntable share one world: the camera sees what the table does."""

from __future__ import annotations

import time

import numpy as np
import pytest

from backend.drivers.base import CameraDriver, CameraSettings, MotionDriver
from backend.drivers.sim import SimCamera, SimMotion, make_sim_world
from tofpose.core.geometry import rotation_angle_deg
from tofpose.lab.motion_profile import SineProfile


@pytest.fixture
def world():
    return make_sim_world(target_distance_mm=15000.0, start_rail_mm=13000.0, seed=3)


def test_drivers_implement_the_protocols(world):
    assert isinstance(SimCamera(world), CameraDriver)
    assert isinstance(SimMotion(world), MotionDriver)


def test_camera_frames_carry_lab_and_exact_truth_at_the_start_range(world):
    cam = SimCamera(world, CameraSettings(frame_rate_hz=50.0))
    f = cam.read(2.0)
    assert f.gray.shape == (240, 320) and f.gray.dtype == np.uint16
    assert f.distance_mm.dtype == np.float32
    np.testing.assert_allclose(f.T_camera_target_lab.t_mm, [0.0, 0.0, 2000.0], atol=0.1)
    # the exact pose is what was rendered: off the lab's by the bench's mount error
    # (paper_mount_error: 0.3 deg and ~2 mm), and the frame's meta carries no pose
    exact, lab = f.T_camera_target_exact, f.T_camera_target_lab
    assert 0.1 < rotation_angle_deg(exact.R, lab.R) < 1.0
    assert 0.5 < np.linalg.norm(exact.t_mm - lab.t_mm) < 50.0
    assert set(f.meta) == {"integration_time_us", "encoders"}
    # Centre pixels see the plate at ~1.85-2 m (radial distance), NaN only where invalid.
    centre = f.distance_mm[110:130, 150:170]
    assert np.nanmedian(centre) == pytest.approx(2000.0, abs=160.0)


def test_frame_rate_is_paced_and_changes_with_settings(world):
    cam = SimCamera(world, CameraSettings(frame_rate_hz=20.0))
    # the clock starts before the first read: the pacer releases that one at once and
    # each later one a period after the previous release, so 7 reads span >= 6 periods
    # however long each render takes (a clock started after a slow first render would
    # not: the next release is due a period after the first *release*)
    t0 = time.monotonic()
    times = [cam.read(1.0).time_s for _ in range(7)]
    # Paced: never faster than the rate (a loaded machine may be slower; that is not
    # the pacer's doing, so only the lower bound is checked on the wall clock).
    assert time.monotonic() - t0 >= 6 / 20.0 - 0.01
    assert np.median(np.diff(times)) >= 0.05 - 0.01
    applied = cam.apply_settings(CameraSettings(frame_rate_hz=5.0, integration_time_us=1e6))
    assert applied.integration_time_us == 4000.0  # clamped to the sensor's limit
    t0 = time.monotonic()
    cam.read(1.0)
    cam.read(1.0)
    assert time.monotonic() - t0 >= 0.2 - 0.01


def test_modulation_frequency_setting_reaches_the_sensor(world):
    cam = SimCamera(world)
    cam.apply_settings(CameraSettings(modulation_frequency_mhz=12.0, auto_exposure=False))
    assert world.bench.sensor.modulation_frequency_hz == 12.0e6
    assert world.bench.sensor.auto_exposure is False


def test_camera_sees_the_turntable_move(world):
    cam = SimCamera(world, CameraSettings(frame_rate_hz=50.0))
    motion = SimMotion(world)
    before = cam.read(1.0).T_camera_target_lab
    motion.move_to({"roll": 4.0})
    assert motion.status().busy
    deadline = time.monotonic() + 5.0
    while not motion.status().settled and time.monotonic() < deadline:
        time.sleep(0.02)
    st = motion.status()
    assert st.settled and abs(st.positions["roll"] - 4.0) < 0.01
    after = cam.read(1.0).T_camera_target_lab
    assert rotation_angle_deg(before.R, after.R) == pytest.approx(4.0, abs=0.01)


def test_stop_freezes_the_axes_where_they_are(world):
    motion = SimMotion(world)
    motion.move_to({"yaw": 100.0})
    time.sleep(0.3)
    motion.stop()
    st = motion.status()
    assert st.stopped and not st.busy
    assert 0.5 < st.positions["yaw"] < 10.0
    time.sleep(0.2)
    assert motion.status().positions["yaw"] == pytest.approx(st.positions["yaw"], abs=0.01)
    motion.move_to({"yaw": 0.0})
    assert not motion.status().stopped


def test_closed_camera_read_times_out(world):
    cam = SimCamera(world, CameraSettings(frame_rate_hz=1.0))
    cam.read(1.0)
    cam.close()
    with pytest.raises(TimeoutError):
        cam.read(0.5)


def test_the_table_follows_a_sine_profile_and_stamps_its_encoders():
    """Status reads during a sine slew: each encoder reading matches the profile at the
    reading's own time stamp, and the rate from consecutive stamped readings matches
    the profile's rate; the status names the profile while it runs."""
    world = make_sim_world(seed=5, time_scale=4.0)
    motion = SimMotion(world)
    assert motion.axes["yaw"].max_accel == 40.0 and motion.profile_unavailable is None
    start = motion.status().positions["yaw"]
    profile = SineProfile(5.0, 4.0, 1)
    motion.run_profile("yaw", profile)
    reads = []
    while (st := motion.status()).profile is not None:
        assert st.busy and st.profile.axis == "yaw" and st.profile.kind == "sine"
        reads.append((st.time_s, st.positions["yaw"], st.profile.elapsed_s))
        time.sleep(0.02)
    t_s, yaw, elapsed = (np.array(c) for c in zip(*reads, strict=True))
    assert len(reads) > 50 and elapsed.max() > 11.0  # 12 s of lab time, seen to the end
    t0 = t_s[0] - elapsed[0]
    assert np.allclose(t_s - elapsed, t0)  # elapsed counts on the encoders' clock
    expected = profile.started_at(start).angle_deg_at(t_s - t0)
    assert np.abs(yaw - expected).max() < 2e-3
    rate = np.diff(yaw) / np.diff(t_s)
    mid = 0.5 * (t_s[1:] + t_s[:-1]) - t0
    assert np.abs(rate - profile.rate_deg_s_at(mid)).max() < 0.1  # noise / ~0.08 s, curvature
    assert np.abs(rate).max() == pytest.approx(profile.peak_rate_deg_s, rel=0.05)
    done = motion.status()
    assert not done.busy and done.positions["yaw"] == pytest.approx(start, abs=2e-3)
