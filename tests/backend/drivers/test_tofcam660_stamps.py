"""The TOFcam-660 driver's stamps through the emulator: the capture time is taken when
the acquisition command goes out, and an image the camera took but the network lost is
a gap in the camera's measurement ids (a camera drop)."""

from __future__ import annotations

import time

import pytest

from backend.drivers.base import CameraError, CameraSettings
from backend.drivers.sim import make_sim_world
from backend.drivers.tofcam660 import TofCam660Driver
from backend.emulators.tofcam660 import TofCam660Emulator
from backend.services.live.latency import SequenceGaps

ADDRESS = "127.0.0.46"
FIXED = CameraSettings(integration_time_us=300.0, auto_exposure=False, frame_rate_hz=60.0)


@pytest.fixture
def emu():
    world = make_sim_world(start_rail_mm=13000.0)
    world.set_sensor(noise=False)
    with TofCam660Emulator(world, ADDRESS) as e:
        yield e


def test_capture_stamp_and_a_lost_image_as_a_counter_gap(emu):
    drv = TofCam660Driver(ADDRESS, settings=FIXED, io_timeout_s=0.5)
    gaps = SequenceGaps()
    try:
        before = time.monotonic_ns()
        first = drv.read(2.0)
        arrived = time.monotonic_ns()
        assert first.capture_ns is not None and before <= first.capture_ns <= arrived
        second = drv.read(2.0)
        assert [gaps.observe(f.sequence) for f in (first, second)] == [0, 0]
        assert second.sequence == first.sequence + 1
        emu.lose_images()  # the camera takes the image, the network loses it
        with pytest.raises(CameraError, match="image lost"):
            drv.read(2.0)
        emu.lose_images(False)
        third = drv.read(2.0)
    finally:
        drv.close()
    # the camera's own counter went on: one image missing between the second and third
    assert third.sequence == second.sequence + 2
    assert gaps.observe(third.sequence) == 1
    assert emu.camera.frames_sent == 4


def test_time_s_is_the_middle_of_the_four_phase_sub_frames(emu):
    """``time_s`` (the instant the pose is of) is the acquisition command's stamp plus
    two integration times and one and a half sub-frame read-outs: the middle of the four
    phase sub-frames, not the image's arrival; monotonic from frame to frame."""
    from backend.drivers.tofcam660 import SUBFRAME_READOUT_S

    drv = TofCam660Driver(ADDRESS, settings=FIXED, io_timeout_s=0.5)
    try:
        frames = [drv.read(2.0) for _ in range(3)]
        arrived_s = time.monotonic()
    finally:
        drv.close()
    for f in frames:
        used_s = f.meta["integration_time_us"] * 1e-6
        assert used_s == pytest.approx(300e-6)
        assert f.capture_ns is not None
        expected = f.capture_ns * 1e-9 + 2.0 * used_s + 1.5 * SUBFRAME_READOUT_S
        assert f.time_s == pytest.approx(expected, abs=1e-9)
    assert frames[0].time_s < frames[1].time_s < frames[2].time_s < arrived_s


def test_the_emulator_renders_the_scene_at_the_instant_the_driver_stamps(emu):
    """The emulated camera renders the scene at the middle of the acquisition its command
    starts (two integration times and 1.5 read-outs after the command's arrival), the
    instant the driver's ``time_s`` names; it used to render at the arrival, so a moving
    scene was that much older than its stamp."""
    from backend.drivers.tofcam660 import SUBFRAME_READOUT_S

    long_exposure = CameraSettings(
        integration_time_us=4000.0, auto_exposure=False, frame_rate_hz=20.0
    )
    drv = TofCam660Driver(ADDRESS, settings=long_exposure, io_timeout_s=0.5)
    try:
        frame = drv.read(2.0)
    finally:
        drv.close()
    assert emu.camera.last_capture_lab_s is not None
    received, rendered = emu.camera.last_capture_lab_s
    used_s = frame.meta["integration_time_us"] * 1e-6
    assert used_s == pytest.approx(4000e-6)
    ahead_s = 2.0 * used_s + 1.5 * SUBFRAME_READOUT_S  # the driver's stamp convention
    assert rendered - received == pytest.approx(ahead_s, abs=5e-4)  # two clock reads apart
    # the same instant on the host's clock, up to the command's trip to the camera
    shown_s = emu.camera.world.host_monotonic_ns(rendered) * 1e-9
    assert frame.capture_ns is not None
    assert frame.capture_ns * 1e-9 < shown_s
    assert shown_s - frame.time_s == pytest.approx(0.0, abs=0.25)
