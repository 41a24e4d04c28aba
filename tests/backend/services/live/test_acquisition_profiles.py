"""``serve --camera replay:REC`` with a recording of another camera than the TOFcam-660:
an Azure Kinect NFOV (640 x 576) or HoloLens 2 AHAT-like (512 x 512, 1 m wrap) recording
(16-bit IR, count scale 16) made by the simulator streams its own frames, at its own size
and gray full scale, and the live pipeline runs with the profile's saturation level,
range and scaled settings and measures the target."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from backend.services.live.frame_codec import (
    decode_raw_frame,
    encode_raw_frame,
    raw_frame_full_scale,
)
from backend.services.live.imaging import gray_u8
from tests.backend.conftest import latest_pose, make_settings, running_app
from tofpose.config import PipelineConfig, TrackingConfig, config_for_camera
from tofpose.core.camera_profiles import load_profile
from tofpose.io.recording import open_recording
from tofpose.workflows.simulation import simulate

PROFILES = {"azure-kinect-nfov": (640, 576), "hololens2-ahat": (512, 512)}


@pytest.fixture(scope="module", params=sorted(PROFILES))
def recording(request, tmp_path_factory):
    """(profile name, a 6-frame recording of the target at 697 mm through it)"""
    path = tmp_path_factory.mktemp("rec") / f"{request.param}.h5"
    simulate("stability-697", 6, str(path), 3, None, progress=False, camera_arg=request.param)
    return request.param, path


def test_the_raw_frame_states_the_cameras_full_scale():
    gray = np.array([[0, 65535], [4095, 7]], np.uint16)
    dist = np.full((2, 2), 1000.0)
    msg = encode_raw_frame(3, gray, dist, full_scale_counts=65535.0)
    assert raw_frame_full_scale(msg) == 65535
    np.testing.assert_array_equal(decode_raw_frame(msg)[2], gray)
    assert raw_frame_full_scale(encode_raw_frame(3, gray, dist)) == 0  # not stated
    with pytest.raises(ValueError, match="full_scale_counts"):
        encode_raw_frame(3, gray, dist, full_scale_counts=-1)


@pytest.mark.parametrize(
    ("full_scale", "counts", "u8"),
    [
        (4095.0, [0, 1024, 4095, 9000], [0, 128, 255, 255]),
        (65535.0, [0, 16384, 65535, 4095], [0, 128, 255, 64]),
    ],
)
def test_gray_images_top_out_at_the_cameras_full_scale(full_scale, counts, u8):
    out = gray_u8(np.array([counts], np.uint16), full_scale)
    assert out.tolist() == [u8]
    with pytest.raises(ValueError, match="full_scale_counts"):
        gray_u8(np.zeros((1, 1), np.uint16), 0.0)


def test_a_replayed_recording_of_another_camera_streams_at_its_own_size_and_scale(
    tmp_path, recording
):
    name, path = recording
    width, height = PROFILES[name]
    profile = load_profile(name)
    with open_recording(path) as rec:
        camera = rec.camera
        recorded = [rec.frame(i)[0] for i in range(rec.n_frames)]
    assert (camera.width, camera.height, camera.full_scale_counts) == (width, height, 65535.0)
    assert camera.count_scale == profile.count_scale == 16.0
    settings = make_settings(tmp_path / "data", camera=f"replay:{path}")
    with running_app(settings) as c:
        acq = c.app.state.tofpose.acquisition
        # the pipeline measures with the recording's camera: its saturation level and its
        # unambiguous range (not the TOFcam-660's 4095 counts and 25 m)
        live = acq.camera.model
        assert live.full_scale_counts == profile.full_scale_counts == 65535.0
        assert live.unambiguous_range_mm == pytest.approx(profile.unambiguous_range_mm)
        assert (live.width, live.height) == (width, height)
        # the pipeline's pixel cap and count thresholds scaled to the camera
        base = PipelineConfig(tracking=TrackingConfig(enabled=settings.tracking))
        want = config_for_camera(base, width=width, height=height, count_scale=16.0)
        assert acq.pipeline_config == want
        ex, ex0 = acq.pipeline_config.extraction, base.extraction
        assert ex.n_max == round(ex0.n_max * width * height / (320 * 240))
        assert ex.min_contrast_counts == 16.0 * ex0.min_contrast_counts
        # the frames the dashboard gets: the camera's size, the recording's pixels, full
        # scale 65535
        with c.websocket_connect("/ws/live") as ws:
            hello = ws.receive_json()
            assert (hello["camera"]["width_px"], hello["camera"]["height_px"]) == (width, height)
            assert hello["camera"]["full_scale_counts"] == 65535.0
            ws.send_text(json.dumps({"raw": True, "image_every": 1, "image_step": 1}))
            while (m := ws.receive()).get("bytes") is None:
                pass
        msg = m["bytes"]
        _, step, gray, _ = decode_raw_frame(msg)
        assert step == 1 and gray.shape == (height, width)
        assert raw_frame_full_scale(msg) == 65535
        assert any(np.array_equal(gray, g) for g in recorded)
        # the target measured on the camera's frames
        pose = latest_pose(c)
        assert pose["ok"] and abs(pose["z_mm"] - 697.0) < 15.0, pose
        # the gray PNG: the camera's size, gray up to its own full scale
        r = c.get("/api/frames/latest/gray.png")
        assert r.status_code == 200
        png = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_GRAYSCALE)
        assert png.shape == (height, width)
        index = int(r.headers["X-Frame-Index"])
        shown = recorded[(index - 1) % len(recorded)]
        np.testing.assert_array_equal(png, gray_u8(shown, 65535.0))
        assert png.max() < 255 or shown.max() >= 65535  # not clipped at 4095


def test_the_tofcam660s_live_settings_are_the_defaults(tmp_path):
    settings = make_settings(tmp_path / "data")
    with running_app(settings) as c:
        acq = c.app.state.tofpose.acquisition
        assert acq.camera.model.width == 320
        assert acq.pipeline_config.extraction == PipelineConfig().extraction
