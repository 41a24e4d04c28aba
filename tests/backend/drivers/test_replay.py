"""Replay of an HDF5 recording as a camera."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from backend.drivers.base import CameraDriver
from backend.drivers.replay import ReplayCamera, recorded_rate_hz
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.io.recording import RecordingError, RecordingWriter


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "rec.h5"
    cam = CameraModel()
    with RecordingWriter(path, cam, paper_target(), with_truth=True) as w:
        for i in range(3):
            gray = np.full(cam.shape, 100 + i, np.uint16)
            dist = np.full(cam.shape, 1000.0 + i, np.float32)
            w.append(gray, dist, 0.04 * i, np.eye(3), np.array([0.0, 0.0, 1000.0 + i]))
    return path


def test_loops_over_the_frames_with_truth_and_stream_time(recording):
    cam = ReplayCamera(recording, rate_hz=100.0)
    assert isinstance(cam, CameraDriver)
    assert cam.recorded_rate_hz == pytest.approx(25.0)
    assert cam.catalog.name == "paper-target"
    frames = [cam.read(1.0) for _ in range(7)]
    assert [int(f.gray[0, 0]) for f in frames] == [100, 101, 102, 100, 101, 102, 100]
    assert [f.meta["loop"] for f in frames] == [0, 0, 0, 1, 1, 1, 2]
    assert [f.meta["discontinuity"] for f in frames] == [
        True,
        False,
        False,
        True,
        False,
        False,
        True,
    ]
    assert all(np.diff([f.time_s for f in frames]) > 0)  # stream time keeps increasing
    assert frames[4].T_camera_target_exact.t_mm[2] == 1001.0
    assert frames[4].T_camera_target_lab is None  # the recording has no /lab_truth
    cam.close()


def test_truth_and_lab_truth_fill_the_exact_and_the_lab_pose(tmp_path):
    """/truth -> ``T_camera_target_exact``, /lab_truth -> ``T_camera_target_lab``, frame
    by frame; neither is left in ``meta``."""
    path = tmp_path / "both.h5"
    cam_model = CameraModel()
    exact_t_mm = [np.array([10.0 * i, -5.0, 2000.0 + i]) for i in range(3)]
    lab_R = Rotation.from_euler("xyz", [0.2, -0.3, 0.1], degrees=True).as_matrix()
    lab_t_mm = [t + np.array([3.0, -2.0, 1.5]) for t in exact_t_mm]
    with RecordingWriter(
        path, cam_model, paper_target(), with_truth=True, with_lab_truth=True
    ) as w:
        for i in range(3):
            gray = np.full(cam_model.shape, 100 + i, np.uint16)
            dist = np.full(cam_model.shape, 1000.0 + i, np.float32)
            w.append(
                gray,
                dist,
                0.04 * i,
                np.eye(3),
                exact_t_mm[i],
                lab_R_camera_target=lab_R,
                lab_t_camera_target_mm=lab_t_mm[i],
            )
    cam = ReplayCamera(path, rate_hz=100.0)
    for k in range(4):  # past the end: the loop restarts at frame 0
        f = cam.read(1.0)
        i = f.meta["recording_index"]
        np.testing.assert_array_equal(f.T_camera_target_exact.R, np.eye(3))
        np.testing.assert_array_equal(f.T_camera_target_exact.t_mm, exact_t_mm[i])
        np.testing.assert_array_equal(f.T_camera_target_lab.R, lab_R)
        np.testing.assert_array_equal(f.T_camera_target_lab.t_mm, lab_t_mm[i])
        assert i == k % 3
        assert set(f.meta) == {"recording_index", "recorded_time_s", "loop", "discontinuity"}
    cam.close()


def test_plays_at_the_recorded_rate_by_default(recording):
    cam = ReplayCamera(recording)
    cam.read(1.0)
    t0 = time.monotonic()
    for _ in range(4):
        cam.read(1.0)
    assert time.monotonic() - t0 == pytest.approx(4 * 0.04, abs=0.04)
    cam.close()


def test_bad_files_raise_recording_error(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        ReplayCamera(tmp_path / "missing.h5")
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    with pytest.raises(RecordingError, match="HDF5"):
        ReplayCamera(junk)


def test_recorded_rate_ignores_bad_stamps():
    assert recorded_rate_hz(np.array([0.0, 0.1, 0.2, 0.2, np.nan, 0.4])) == pytest.approx(10.0)
    assert recorded_rate_hz(np.array([5.0])) == 10.0
