"""A campaign's raw recording keeps a wall clock, encoders and set-point per frame, in
step with its frames through truncation and reopening (a paused and resumed campaign)."""

from __future__ import annotations

import numpy as np

from backend.services.campaigns.campaign_recording import CampaignRecordingWriter
from tofpose.core.camera import CameraModel
from tofpose.io.interop.motion_track import read_motion_track
from tofpose.io.recording import RecordingWriter, open_recording

AXES = {"yaw": "deg", "pitch": "deg", "roll": "deg", "rail": "mm"}


def _frame(camera: CameraModel, k: int):
    gray = np.full((camera.height, camera.width), k, np.uint16)
    return gray, np.full(gray.shape, 1000.0 + k, np.float32), 0.1 * k


def _append(w: CampaignRecordingWriter, camera: CameraModel, k: int) -> None:
    w.append(*_frame(camera, k))
    w.append_motion(
        1_700_000_000_000_000_000 + k * 10**8,
        {"yaw": 0.5 * k, "pitch": -1.0, "roll": 0.0, "rail": 12000.0},
        {"yaw": float(k // 2), "rail": 12000.0},  # pitch and roll left alone
        k // 2,
    )


def test_frames_and_their_turntable_rows_stay_in_step_across_truncate_and_reopen(tmp_path):
    camera = CameraModel()
    path = tmp_path / "campaign-1.h5"
    with CampaignRecordingWriter(path, camera, None, axes=AXES) as w:
        for k in range(5):
            _append(w, camera, k)
        w.truncate(3)  # a set-point that did not complete
    with CampaignRecordingWriter.reopen(path) as w:
        assert w.n == 3 and w.axes == tuple(AXES)
        _append(w, camera, 7)
    with open_recording(path) as rec:
        n = rec.n_frames
        assert n == 4 and rec.frame(3)[0][0, 0] == 7
        np.testing.assert_array_equal(
            rec.wall_time_ns, [1_700_000_000_000_000_000 + k * 10**8 for k in (0, 1, 2, 7)]
        )
    track = read_motion_track(path, n)
    assert track is not None and track.fields == ("yaw_deg", "pitch_deg", "roll_deg", "rail_mm")
    np.testing.assert_array_equal(track.positions[:, 0], [0.0, 0.5, 1.0, 3.5])
    np.testing.assert_array_equal(track.targets[:, 0], [0.0, 0.0, 1.0, 3.0])
    assert np.isnan(track.targets[:, 1:3]).all()
    assert track.setpoint_index is not None
    np.testing.assert_array_equal(track.setpoint_index, [0, 0, 1, 3])


def test_a_recording_begun_without_the_rows_is_continued_without_them(tmp_path):
    camera = CameraModel()
    path = tmp_path / "old.h5"
    with RecordingWriter(path, camera) as w:
        w.append(*_frame(camera, 0))
    with CampaignRecordingWriter.reopen(path) as w:
        _append(w, camera, 1)  # the frame is written, the turntable row is not
        w.truncate(2)
    with open_recording(path) as rec:
        assert rec.n_frames == 2 and rec.wall_time_ns is None
    assert read_motion_track(path, 2) is None
