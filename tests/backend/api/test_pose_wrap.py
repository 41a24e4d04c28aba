"""A pose from distances read beyond the camera's unambiguous range, in the pose's public
form (issue 49): ``distances_read_about_mm`` says about which range the distances were
read; null for a frame taken as measured."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest

from backend.api.presenters import pose_from_sample
from backend.api.schemas.pose import PosePublic
from backend.drivers.base import CameraFrame
from backend.services.live.acquisition import LiveSample
from tests.backend.conftest import AUTH, make_settings, running_app, wait_for
from tofpose.config import PipelineConfig, config_for_camera
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline
from tofpose.sim.randomise import draw_frame


@pytest.mark.parametrize(("range_m", "read_further"), [(8.0, True), (4.5, False)])
def test_the_public_pose_says_when_its_distances_were_read_further(range_m, read_further):
    catalog = paper_target()
    drawn = draw_frame("other sensor", range_m, np.random.default_rng(0), catalog)
    cam = drawn.camera  # 20 MHz: the distances wrap at 7.49 m
    config = config_for_camera(
        PipelineConfig(), width=cam.width, height=cam.height, count_scale=cam.count_scale
    )
    f = drawn.render(np.random.default_rng(1))
    res = PosePipeline(cam, catalog, config).process(f.gray, f.distance_mm)
    assert res.ok, res.reason
    frame = CameraFrame(gray=f.gray, distance_mm=f.distance_mm, time_s=1.0, index=3)
    body = json.loads(
        pose_from_sample(LiveSample(frame, res, catalog.name, 1.0, 1.01)).model_dump_json()
    )
    jsonschema.validate(body, PosePublic.model_json_schema(mode="serialization"))
    about = body["distances_read_about_mm"]
    if read_further:
        true_range_mm = float(np.linalg.norm(drawn.T_camera_target.t_mm))
        assert about == pytest.approx(true_range_mm, abs=500.0)
        assert about > cam.unambiguous_range_mm
    else:
        assert about is None


def test_the_live_pose_reads_further_once_the_modulation_frequency_makes_the_range_wrap(
    tmp_path,
):
    """Through the server: the simulated lab at 7 m. At the default 6 MHz (25 m
    unambiguous) the distances are taken as measured; at 24 MHz (6.25 m) they wrap, the
    live pipeline takes the camera's new frequency, and the pose is read one range
    further, at the lab's 7 m."""
    with running_app(make_settings(tmp_path, sim_start_rail_mm=8000.0)) as client:

        def latest() -> dict:
            return client.get("/api/pose/latest").json()

        first = wait_for(lambda: (p := latest()).get("ok") and p, 60.0, "a first ok pose")
        assert first["distances_read_about_mm"] is None
        assert first["z_mm"] == pytest.approx(7000.0, abs=300.0)
        r = client.put(
            "/api/camera/settings", json={"modulation_frequency_mhz": 24.0}, headers=AUTH
        )
        assert r.status_code == 200, r.text
        assert r.json()["unambiguous_range_mm"] < 7000.0
        read = wait_for(
            lambda: (p := latest()).get("ok") and p.get("distances_read_about_mm") and p,
            60.0,
            "an ok pose read one unambiguous range further",
        )
        assert read["z_mm"] == pytest.approx(7000.0, abs=300.0)
        assert read["distances_read_about_mm"] == pytest.approx(7000.0, abs=500.0)
