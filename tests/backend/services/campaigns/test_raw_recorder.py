"""A campaign's raw recording (``RawRecorder``) holds one camera model: ``/camera`` is the
model its first frame was taken with (``LiveSample.camera_model``, not the one given at
the start, which predates the first set-point's settings), and a frame taken at another
modulation frequency (a campaign resumed after the camera's own frequency changed) is
refused with a reason that names both, the file unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from backend.services.campaigns.campaign_repository import RawRecorder, RawRecordingError
from tests.backend.services.test_recordings import CAMERA, make_sample
from tofpose.core.catalog import paper_target
from tofpose.io.recording import open_recording

AT_6 = replace(CAMERA, modulation_frequency_hz=6e6)
AT_12 = replace(CAMERA, modulation_frequency_hz=12e6)


def test_the_file_holds_the_first_frames_model_and_refuses_another_frequency(tmp_path):
    path = tmp_path / "campaign-1.h5"
    rng = np.random.default_rng(2)
    recorder = RawRecorder(path, AT_6, paper_target(), committed_frames=0)
    try:
        for i in range(2):
            recorder.append(replace(make_sample(i, rng), camera_model=AT_12))
        with pytest.raises(RawRecordingError, match="is 6 MHz.*taken at 12 MHz"):
            recorder.append(replace(make_sample(2, rng), camera_model=AT_6))
        # a sample that does not carry its model is taken as the one given
        with pytest.raises(RawRecordingError):
            recorder.append(make_sample(3, rng))
        recorder.flush()
    finally:
        recorder.close()
    with open_recording(path) as rec:
        assert rec.n_frames == 2
        assert rec.camera.modulation_frequency_hz == 12e6
    # resumed: the file's model is read back and holds as before
    again = RawRecorder(path, AT_6, paper_target(), committed_frames=2)
    try:
        with pytest.raises(RawRecordingError, match="set the camera to 12 MHz"):
            again.append(replace(make_sample(4, rng), camera_model=AT_6))
        assert again.append(replace(make_sample(5, rng), camera_model=AT_12)) == 2
    finally:
        again.close()


def test_a_file_rolled_back_to_its_start_takes_the_next_frames_model(tmp_path):
    """A set-point that did not complete leaves a file without frames: its ``/camera``
    says nothing of any frame, so the next frame may be at another frequency, and the
    file is written again with that frame's model."""
    path = tmp_path / "campaign-2.h5"
    rng = np.random.default_rng(4)
    recorder = RawRecorder(path, AT_6, paper_target(), committed_frames=0)
    try:
        recorder.append(replace(make_sample(0, rng), camera_model=AT_6))
        recorder.rollback(0)
        recorder.check_camera(AT_12)  # nothing held: no objection
        assert recorder.append(replace(make_sample(1, rng), camera_model=AT_12)) == 0
        recorder.flush()
    finally:
        recorder.close()
    with open_recording(path) as rec:
        assert rec.n_frames == 1 and rec.camera.modulation_frequency_hz == 12e6


def test_the_check_before_a_move_says_what_to_do(tmp_path):
    """``check_camera`` runs once a set-point's settings are applied, before it moves:
    the advice depends on who chose the frequency (the camera's own: set it back; the
    campaign's settings: a new campaign)."""
    rng = np.random.default_rng(6)
    recorder = RawRecorder(tmp_path / "campaign-3.h5", AT_6, paper_target(), committed_frames=0)
    try:
        recorder.check_camera(AT_12)  # an empty file holds no frequency yet
        recorder.append(replace(make_sample(0, rng), camera_model=AT_6))
        recorder.check_camera(AT_6)
        with pytest.raises(RawRecordingError, match="set the camera to 6 MHz and resume"):
            recorder.check_camera(AT_12)
        with pytest.raises(RawRecordingError, match="measure at 12 MHz in a new campaign"):
            recorder.check_camera(AT_12, set_by_campaign=True)
    finally:
        recorder.close()
