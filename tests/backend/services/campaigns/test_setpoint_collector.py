"""The set-point collector on the simulated lab, without a database or the acquisition
thread: the camera is read and measured in the test's own thread. Known truth: the
set-point the table reached (its encoders), when the table reported settled (its status
on the lab clock, which the frames share), and every device fault the test injects."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from backend.drivers.base import CameraSettings
from backend.drivers.sim import SimCamera, SimMotion, make_sim_world
from backend.services.campaigns.campaign_states import CampaignState
from backend.services.campaigns.setpoint_collector import (
    AT_SETPOINT_TOLERANCE,
    MAX_UNSETTLED_FRAMES,
    CollectPolicy,
    CollectTiming,
    SetPointCollector,
    SetPointHalt,
)
from backend.services.live.acquisition import DeviceHealth, LiveSample
from backend.services.motion import MotionService
from tests.backend.conftest import FlakyCamera, SpyMotion
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline

SETPOINT = {"yaw": 4.0, "pitch": -3.0, "roll": 2.0, "rail": 12000.0}
POLICY = CollectPolicy(frames=6, settle_s=1.0, lock_timeout_s=2.0)
TIME_SCALE = 5.0  # the lab runs 5x faster than the wall clock; frames at 20 Hz wall


class PipelineFrames:
    """A ``FrameSource`` that reads the camera and runs the pipeline when asked, in the
    caller's thread (what the acquisition loop does in its own); a read that fails is
    recorded in ``health`` as the loop records it."""

    def __init__(self, camera) -> None:
        self.camera = camera
        self.pipeline = PosePipeline(camera.model, paper_target())
        self.health = DeviceHealth()

    def get(self, timeout_s: float) -> LiveSample | None:
        try:
            frame = self.camera.read(timeout_s)
        except TimeoutError:
            return None
        except Exception as exc:
            self.health.record_failure(f"camera failed: {exc}")
            return None
        self.health.record_ok()
        result = self.pipeline.process(frame.gray, frame.distance_mm, frame.time_s)
        now = time.time()
        return LiveSample(frame, result, "paper-target", now, now)

    def drain(self) -> None:
        return None  # nothing waits: a frame is read when asked for


class StatusLog(SpyMotion):
    """Records every status the collector reads (the lab clock stamps each)."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        self.statuses = []

    def status(self):
        st = self.inner.status()
        self.statuses.append(st)
        return st


@pytest.fixture
def lab():
    world = make_sim_world(time_scale=TIME_SCALE)
    camera = FlakyCamera(SimCamera(world, CameraSettings(frame_rate_hz=20.0)))
    driver = StatusLog(SimMotion(world))
    yield world, camera, driver
    camera.close()


def _collector(lab, **kw) -> SetPointCollector:
    _, camera, driver = lab
    kw.setdefault("timing", CollectTiming(poll_s=0.02, move_timeout_s=30.0, frame_timeout_s=2.0))
    return SetPointCollector(MotionService(driver), PipelineFrames(camera), **kw)


def _halt(collect) -> SetPointHalt:
    with pytest.raises(SetPointHalt) as info:
        collect()
    return info.value


def test_the_frames_are_taken_at_the_setpoint_after_the_settle_time(lab):
    _, _, driver = lab
    seen = []
    collector = _collector(lab, on_frame=lambda sample, n: seen.append(n))
    record = collector.collect(3, SETPOINT, POLICY)
    assert record.index == 3 and record.axes == SETPOINT
    assert len(record.frames) == POLICY.frames and seen == list(range(1, POLICY.frames + 1))
    assert driver.calls[0] == ("move_to", SETPOINT)
    settled = next(st for st in driver.statuses if st.settled and not st.busy)
    times = [float(f.sample.frame.time_s) for f in record.frames]
    assert min(times) >= settled.time_s + POLICY.settle_s  # the settle policy, in lab time
    assert np.all(np.diff(times) > 0)
    for f in record.frames:
        enc = f.sample.frame.meta["encoders"]
        for axis, value in SETPOINT.items():
            assert abs(enc[axis] - value) <= AT_SETPOINT_TOLERANCE[axis]
        assert f.in_motion is None and f.sample.result.ok
        # the pose measured is the one rendered at the set-point
        exact = f.sample.frame.T_camera_target_exact
        assert np.linalg.norm(f.sample.result.t_mm - exact.t_mm) < 30.0


def test_no_axes_means_no_move_and_frames_at_once(lab):
    _, _, driver = lab
    record = _collector(lab).collect(0, {}, replace(POLICY, frames=2, settle_s=0.0))
    assert len(record.frames) == 2 and driver.calls == [] and driver.statuses == []


def test_a_camera_that_drops_out_pauses_naming_the_camera_state(lab):
    _, camera, _ = lab
    collector = _collector(lab, on_frame=lambda sample, n: camera.failing.set())
    halt = _halt(lambda: collector.collect(1, SETPOINT, POLICY))
    assert halt.status is CampaignState.PAUSED
    assert halt.reason == (
        "no frame for 2 s at set-point 1 (camera degraded: camera failed: camera unplugged (test))"
    )


def test_a_motion_system_that_drops_out_pauses_and_degrades_its_health(lab):
    _, _, driver = lab
    calls = 0

    def dying():
        nonlocal calls
        calls += 1
        if calls > 2:
            raise ConnectionError("rate table link lost")
        return driver.inner.status()

    driver.status = dying
    collector = _collector(lab)
    halt = _halt(lambda: collector.collect(2, SETPOINT, POLICY))
    assert (halt.status, halt.reason) == (
        CampaignState.PAUSED,
        "motion status failed at set-point 2: rate table link lost",
    )
    assert collector.motion.health.state == "degraded"
    assert collector.motion.health.last_error == "motion status failed: rate table link lost"


def test_a_setpoint_outside_the_soft_limits_pauses_before_the_driver_moves(lab):
    _, _, driver = lab
    halt = _halt(lambda: _collector(lab).collect(0, {"yaw": 1000.0}, POLICY))
    assert halt.status is CampaignState.PAUSED
    assert halt.reason.startswith(
        "move to set-point 0 failed: yaw set-point 1000 deg is outside the soft limits"
    )
    assert driver.calls == []


class LateFrames(PipelineFrames):
    """The first ``n_late`` frames after a settle carry the encoders of the move (the
    rail 50 mm short), as frames captured while the table moved and measured late on a
    loaded machine arrive after the motion service reports settled."""

    def __init__(self, camera, n_late: int) -> None:
        super().__init__(camera)
        self.n_late = n_late

    def get(self, timeout_s: float) -> LiveSample | None:
        sample = super().get(timeout_s)
        if sample is None or self.n_late <= 0:
            return sample
        self.n_late -= 1
        enc = {**sample.frame.meta["encoders"], "rail": SETPOINT["rail"] - 50.0}
        frame = replace(sample.frame, meta={**sample.frame.meta, "encoders": enc})
        return replace(sample, frame=frame)


@pytest.mark.parametrize("n_late", [6, MAX_UNSETTLED_FRAMES + 1])
def test_frames_of_the_move_arriving_after_the_settle_are_not_counted(lab, n_late):
    """Late frames still off the set-point, over more than the settle time (six frames
    at 0.25 s of lab time each against a 1 s settle), are passed over, and the settle
    time counts from the first frame at it (counted from the first frame after the
    settle, the fifth and sixth paused the set-point); more than
    ``MAX_UNSETTLED_FRAMES`` of them say the table is not at its set-point."""
    _, camera, driver = lab
    timing = CollectTiming(poll_s=0.02, move_timeout_s=30.0, frame_timeout_s=2.0)
    collector = SetPointCollector(MotionService(driver), LateFrames(camera, n_late), timing=timing)
    if n_late > MAX_UNSETTLED_FRAMES:
        halt = _halt(lambda: collector.collect(2, SETPOINT, POLICY))
        assert halt.reason == "the turntable left set-point 2 (axes ['rail'])"
        return
    record = collector.collect(2, SETPOINT, POLICY)
    assert len(record.frames) == POLICY.frames
    for f in record.frames:
        assert abs(f.sample.frame.meta["encoders"]["rail"] - SETPOINT["rail"]) <= 1.0


def test_the_table_leaving_the_setpoint_pauses(lab):
    world, _, _ = lab
    collector = _collector(lab, on_frame=lambda sample, n: world.move_to({"yaw": 10.0}))
    halt = _halt(lambda: collector.collect(4, SETPOINT, POLICY))
    assert (halt.status, halt.reason) == (
        CampaignState.PAUSED,
        "the turntable left set-point 4 (axes ['yaw'])",
    )


def test_a_stop_pressed_while_settling_pauses(lab):
    world, _, _ = lab
    collector = _collector(lab)
    collector.check = lambda index: world.stop()  # STOP pressed on the controller
    halt = _halt(lambda: collector.collect(5, {"yaw": 30.0}, POLICY))
    assert halt.reason == "the turntable was stopped at set-point 5"


def test_a_persons_stop_found_by_the_runner_first_reads_stop_pressed(lab):
    """The motion service latches a person's STOP and stops the table before it tells
    the campaign service; a runner that sees the stopped table first names the same
    cause as the campaign service's own request would."""
    world, _, _ = lab
    collector = _collector(lab)

    checks = []

    def person_presses_stop(index: int) -> None:
        checks.append(index)
        if len(checks) == 2:  # the move is sent: STOP while the table settles
            collector.motion.latch_stop()
            world.stop()

    collector.check = person_presses_stop
    halt = _halt(lambda: collector.collect(7, {"yaw": 30.0}, POLICY))
    assert (halt.status, halt.reason) == (CampaignState.PAUSED, "STOP pressed at set-point 7")


def test_a_lost_pose_lock_pauses_after_the_lock_timeout(lab):
    _, camera, _ = lab
    inner_read = camera.read

    def blank(timeout_s):
        f = inner_read(timeout_s)
        # the target is gone: dark and out of range
        return replace(
            f, gray=np.zeros_like(f.gray), distance_mm=np.full_like(f.distance_mm, np.nan)
        )

    camera.read = blank
    many = replace(POLICY, frames=100)  # more than the lock timeout lasts
    halt = _halt(lambda: _collector(lab).collect(6, SETPOINT, many))
    assert halt.status is CampaignState.PAUSED
    assert halt.reason.startswith("pose lock lost for ") and " s at set-point 6: " in halt.reason
    lost_s = float(halt.reason.split()[4])
    assert POLICY.lock_timeout_s <= lost_s <= POLICY.lock_timeout_s + 1.5  # frames: 0.25 s apart


def test_the_callers_check_leaves_the_setpoint_with_its_state(lab):
    collector = _collector(lab)
    frames = []

    def check(index):
        if len(frames) >= 2:
            raise SetPointHalt(CampaignState.CANCELLED, f"cancelled (during set-point {index})")

    collector.check, collector.on_frame = check, lambda sample, n: frames.append(n)
    halt = _halt(lambda: collector.collect(7, SETPOINT, POLICY))
    assert (halt.status, halt.reason) == (CampaignState.CANCELLED, "cancelled (during set-point 7)")
    assert frames == [1, 2]


def test_a_dynamic_setpoint_keeps_every_frame_and_marks_those_in_motion(lab):
    _, _, driver = lab
    spec = {
        "axis": "yaw",
        "kind": "sine",
        "amplitude_deg": 2.0,
        "period_s": 2.0,
        "cycles": 1,
        "rest_s": 0.5,
    }
    collector = _collector(lab, owner=9)
    collector.motion.claim(9, "dynamic")
    record = collector.collect_profile(0, {"yaw": 0.0, "rail": 12000.0}, spec, settle_s=0.3)
    names = [name for name, _ in driver.calls]
    assert names == ["move_to", "run_profile"]
    flags = [f.in_motion for f in record.frames]
    assert flags[0] is False and flags[-1] is False and sum(flags) >= 10
    first_in = flags.index(True)
    assert all(flags[first_in : first_in + sum(flags)])  # one stretch in motion
    yaw = [f.sample.frame.meta["encoders"]["yaw"] for f in record.frames if f.in_motion]
    assert max(np.abs(yaw)) > 1.0  # the frames in motion saw the slew (amplitude 2 deg)
    assert not driver.inner.status().busy


def test_a_pause_while_the_table_travels_stops_it(lab):
    """A pause (or cancel, or shutdown) that comes while the table is on its way to the
    set-point stops the table before the campaign gives the motion system back: nobody
    may move a table that is still travelling, and a paused campaign's move does not go
    on (a profile's slew was already stopped the same way)."""
    _, _, driver = lab
    collector = _collector(lab)
    checks = []

    def check(index):
        checks.append(index)
        if len(checks) >= 3:  # the move has started; the table is travelling
            raise SetPointHalt(CampaignState.PAUSED, f"paused (during set-point {index})")

    collector.check = check
    halt = _halt(lambda: collector.collect(8, {"yaw": 40.0}, POLICY))
    assert halt.reason == "paused (during set-point 8)"
    names = [c for c, _ in driver.calls]
    assert names.index("move_to") < names.index("stop")  # the stop after the move it ends
    assert not driver.inner.status().busy  # nothing travels once the campaign lets go
