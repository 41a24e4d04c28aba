"""Saturated reflectors in the pose's public form (issue 49, item 2): each matched
reflector's ``saturated`` and the frame's ``saturated_reflectors``, on GET
/api/pose/latest, /api/pose/history and /ws/live."""

from __future__ import annotations

import json

import jsonschema
import pytest

from backend.api.presenters import pose_from_sample
from backend.api.schemas.pose import PosePublic
from backend.drivers.base import CameraFrame
from backend.services.live.acquisition import LiveSample
from tests.backend.conftest import AUTH, wait_for
from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline
from tofpose.sim.render import SensorModel
from tofpose.sim.scene import FIRST_DISC


def _sample(sensor: SensorModel | None) -> tuple[LiveSample, dict[int, bool]]:
    """A live sample of a frame at 2 m, 25 deg of yaw, and per catalog id whether a pixel
    the simulator saw on that reflector's disc reads at full scale."""
    cam, catalog = CameraModel(), paper_target()
    T = facing_pose(2000.0, yaw_deg=25.0)
    f = render(T, seed=1, sensor=sensor)
    truth = {
        int(i): bool((f.gray[f.surface_id == FIRST_DISC + k] >= cam.full_scale_counts).any())
        for k, i in enumerate(catalog.ids)
    }
    res = PosePipeline(cam, catalog).process(f.gray, f.distance_mm)
    assert res.ok, res.reason
    frame = CameraFrame(gray=f.gray, distance_mm=f.distance_mm, time_s=1.0, index=3)
    return LiveSample(frame, res, catalog.name, 1.0, 1.01), truth


@pytest.mark.parametrize(
    ("sensor", "n_saturated"),
    [
        (None, 0),  # auto exposure: nothing clips
        (SensorModel(auto_exposure=False, integration_time_us=800.0), 2),  # 7 and 8 clip
    ],
)
def test_a_matched_reflector_that_saturates_says_so(sensor, n_saturated):
    sample, truth = _sample(sensor)
    body = json.loads(pose_from_sample(sample).model_dump_json())
    jsonschema.validate(body, PosePublic.model_json_schema(mode="serialization"))
    flags = {m["catalog_id"]: m["saturated"] for m in body["matched"]}
    assert flags == {i: truth[i] for i in flags} and len(flags) == 8
    assert body["saturated_reflectors"] == n_saturated == sum(truth.values())


def test_the_live_pose_counts_saturated_reflectors_after_a_long_fixed_exposure(client):
    """Through the server: the simulated camera with auto exposure off and a long
    integration time at 2 m clips the reflectors; REST and WebSocket say so."""

    def latest() -> dict:
        return client.get("/api/pose/latest").json()

    first = wait_for(lambda: (p := latest()).get("ok") and p, 60.0, "a first ok pose")
    assert first["saturated_reflectors"] == 0
    assert not any(m["saturated"] for m in first["matched"])
    r = client.put(
        "/api/camera/settings",
        json={"auto_exposure": False, "integration_time_us": 4000.0},
        headers=AUTH,
    )
    assert r.status_code == 200, r.text
    clipped = wait_for(
        lambda: (p := latest()).get("saturated_reflectors", 0) > 0 and p,
        60.0,
        "a pose with saturated reflectors",
    )
    assert clipped["saturated_reflectors"] == sum(m["saturated"] for m in clipped["matched"])
    history = client.get("/api/pose/history", params={"n": 5}).json()
    assert history[-1]["saturated_reflectors"] > 0
    assert all("saturated" in m for p in history for m in p["matched"])
    with client.websocket_connect("/ws/live") as ws:
        while (m := ws.receive_json())["type"] != "pose":
            pass
    pose = m["data"]
    assert pose["saturated_reflectors"] == sum(x["saturated"] for x in pose["matched"]) > 0
