"""The dashboard with another camera: a replayed Azure Kinect NFOV recording (640 x 576,
16-bit IR) is drawn at its own size and aspect ratio, its gray up to the camera's full
scale (65535), with the pose measured on it."""

from __future__ import annotations

import numpy as np
import pytest

from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS
from tofpose.io.recording import open_recording
from tofpose.workflows.simulation import simulate


@pytest.fixture
def kinect_server(tmp_path):
    rec = tmp_path / "ak.h5"
    simulate("stability-697", 6, str(rec), 3, None, progress=False, camera_arg="azure-kinect-nfov")
    with LiveServer(make_settings(tmp_path / "data", camera=f"replay:{rec}")) as srv:
        yield srv, rec


def test_a_replayed_azure_kinect_recording_is_drawn_at_its_own_size_and_scale(
    kinect_server, page_for
):
    server, rec = kinect_server
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("frame-index").wait_for(timeout=20_000)
    page.get_by_test_id("pose-x").wait_for(timeout=20_000)
    canvas = page.evaluate(
        """() => { const c = document.querySelector('[data-testid=image-gray]');
                   const f = document.querySelector('[data-testid=frame-gray]')
                                     .getBoundingClientRect();
                   const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                   const g = []; for (let i = 0; i < d.length; i += 4) g.push(d[i]);
                   return {w: c.width, h: c.height, fw: f.width, fh: f.height, gray: g}; }"""
    )
    assert (canvas["w"], canvas["h"]) == (640, 576)
    # the frame on the page has the camera's aspect ratio, not the TOFcam-660's 4:3
    assert canvas["fw"] / canvas["fh"] == pytest.approx(640 / 576, rel=0.01)
    assert "0–65535" in page.get_by_test_id("gray-scale").inner_text()
    # the overlay keeps ~640 canvas pixels across (1 per image pixel here, 2 on a 320-px
    # camera), so its marks and labels keep their size on the page
    overlay = page.evaluate(
        "Array.from(document.querySelectorAll('[data-testid=overlay]'), c => [c.width, c.height])"
    )
    assert overlay == [[640, 576], [640, 576]]
    # the drawn gray is gamma 0.5 of the counts over 65535: the one of the recording's
    # frames it shows matches to the rounding
    drawn = np.array(canvas["gray"], float).reshape(576, 640)
    with open_recording(rec) as r:
        frames = [r.frame(i)[0] for i in range(r.n_frames)]
    expected = [np.sqrt(g / 65535.0) * 255.0 for g in frames]
    assert min(np.max(np.abs(drawn - e)) for e in expected) <= 1.0
    assert 0 < drawn.max() < 255  # not clipped white at a 12-bit camera's 4095
    z_text = page.get_by_test_id("pose-z").inner_text()
    assert abs(float(z_text) - 697.0) < 15.0, z_text
    page.screenshot(path=str(SHOTS / "dashboard-azure-kinect-replay.png"), full_page=False)
