"""A replay's capture stamps are its recorded stamps mapped to playback: spaced as
recorded (scaled by the playback rate), never after the frame was released, and
anchored afresh at each loop; its counter has no gap."""

from __future__ import annotations

import time

import numpy as np

from backend.drivers.replay import ReplayCamera
from tofpose.core.camera import CameraModel
from tofpose.io.recording import RecordingWriter

CAMERA = CameraModel(width=40, height=30, fx=40.0, fy=40.0, cx=19.5, cy=14.5, name="small")


def test_capture_stamps_follow_the_recorded_stamps(tmp_path):
    path = tmp_path / "rec.h5"
    recorded_s = [0.0, 0.1, 0.2, 0.3]  # 10 frames/s
    with RecordingWriter(path, CAMERA) as w:
        for t in recorded_s:
            w.append(np.zeros((30, 40), np.uint16), np.ones((30, 40), np.float32), t)
    cam = ReplayCamera(path, rate_hz=20.0)  # played twice as fast
    try:
        frames, released = [], []
        for _ in range(6):
            f = cam.read(2.0)
            released.append(time.monotonic_ns())
            frames.append(f)
    finally:
        cam.close()
    capture = np.array([f.capture_ns for f in frames])
    assert (capture <= np.array(released)).all()
    # within a loop: 0.1 s recorded -> 50 ms played (less when a release came late and
    # the mapping was anchored afresh; a loaded machine may do that)
    steps_ms = np.diff(capture[:4]) / 1e6
    assert abs(np.median(steps_ms) - 50.0) < 1.0, steps_ms
    assert [f.sequence for f in frames] == [1, 2, 3, 4, 5, 6]
    assert [f.meta["recording_index"] for f in frames] == [0, 1, 2, 3, 0, 1]
