"""Integration: the app on a temp SQLite file with simulated devices."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from backend.settings import Settings
from tests.backend.conftest import AUTH, TOKEN, latest_pose, make_settings, running_app, wait_for


def _R(p: dict) -> np.ndarray:
    q = p["quaternion_wxyz"]
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def _reference_R(p: dict) -> np.ndarray:
    t = p["reference"]
    return Rotation.from_euler("xyz", [t["pitch_deg"], t["yaw_deg"], t["roll_deg"]], degrees=True)


def test_health_reports_devices_and_database(client):
    r = client.get("/api/health")
    assert r.status_code == 200
    h = r.json()
    assert h["database"] == "ok"
    assert h["camera"]["driver"] == "sim" and h["motion"]["driver"] == "sim"
    latest_pose(client)
    h = client.get("/api/health").json()
    assert h["status"] == "ok" and h["camera"]["state"] == "ok"


# Load: the pipeline lags the camera; the waits for the move and a post-settle pose can time out.
@pytest.mark.load_sensitive
def test_live_pose_is_accurate_and_follows_the_turntable(client):
    before = latest_pose(client)
    # The simulated lab starts with the camera 2 m from the target (rail 13 m of 15 m).
    assert abs(before["z_mm"] - 2000.0) < 30.0
    assert before["n_matched"] == 8
    assert before["reference"]["position_error_mm"] < 25.0  # unknown mount error ~0.3 deg
    # Attitude as people read it: face-on reads ~(0, 0, 0), never +-180 (the raw
    # quaternion is that of R_camera_target = diag(1, -1, -1): w ~ 0, x ~ 1).
    assert max(abs(before[k]) for k in ("pitch_deg", "yaw_deg", "roll_deg")) < 1.5
    assert max(abs(before["reference"][k]) for k in ("pitch_deg", "yaw_deg", "roll_deg")) < 1.5
    assert abs(before["quaternion_wxyz"][1]) > 0.99
    r = client.post("/api/motion/move", json={"yaw_deg": 10.0, "roll_deg": -5.0}, headers=AUTH)
    assert r.status_code == 202, r.text
    assert r.json()["targets"]["yaw"] == 10.0
    wait_for(lambda: client.get("/api/motion").json()["busy"], 2.0, "the move to start")
    wait_for(lambda: client.get("/api/motion").json()["settled"], 10.0, "the move to settle")
    # A frame rendered from the turntable's state before the settle can arrive after it
    # (captured_unix_s is its arrival): the frame after the first one to arrive after the
    # settle was rendered from the state at rest.
    settled_unix_s = time.time()

    def arrived_after_settle():
        p = latest_pose(client)
        return p if p["captured_unix_s"] > settled_unix_s else None

    first = wait_for(arrived_after_settle, what="a pose that arrived after the settle")
    after = latest_pose(client, first["frame_index"])
    motion = client.get("/api/motion").json()
    assert abs(motion["positions"]["yaw"] - 10.0) < 0.01
    # The measured relative rotation is the commanded one (11.2 deg geodesic), to 0.2 deg.
    measured = np.degrees(Rotation.from_matrix(_R(before).T @ _R(after)).magnitude())
    turned = (_reference_R(before).inv() * _reference_R(after)).magnitude()
    assert abs(np.degrees(turned) - 11.18) < 0.05
    assert abs(measured - np.degrees(turned)) < 0.2
    # Yawing the camera by +10 deg moves the target towards -x in the image frame.
    assert after["x_mm"] < before["x_mm"] - 300.0


def test_stop_halts_a_move_midway(client):
    latest_pose(client)
    assert (
        client.post("/api/motion/move", json={"roll_deg": 170.0}, headers=AUTH).status_code == 202
    )
    wait_for(
        lambda: abs(client.get("/api/motion").json()["positions"]["roll"]) > 5.0,
        5.0,
        "the roll axis to move",
    )
    r = client.post("/api/motion/stop", headers=AUTH)
    assert r.status_code == 200
    stopped_at = r.json()["positions"]["roll"]
    assert r.json()["stopped"] is True
    wait_for(lambda: not client.get("/api/motion").json()["busy"], 2.0, "the stop")
    later = client.get("/api/motion").json()["positions"]["roll"]
    assert 5.0 < later < 60.0 and abs(later - stopped_at) < 3.0


def test_auth_required_for_every_state_change(client):
    changes = [
        ("post", "/api/motion/move", {"yaw_deg": 1.0}),
        ("post", "/api/motion/stop", None),
        ("put", "/api/camera/settings", {"frame_rate_hz": 15.0}),
        ("post", "/api/catalogs", {"name": "x", "reflectors": []}),
        ("post", "/api/catalogs/paper-target/activate", None),
    ]
    for method, path, body in changes:
        for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": TOKEN}):
            r = client.request(method, path, json=body, headers=headers)
            assert r.status_code == 401, (method, path, headers, r.text)
            assert "token" in r.json()["detail"].lower()
    assert client.post("/api/motion/stop", headers=AUTH).status_code == 200
    assert (
        client.put("/api/camera/settings", json={"frame_rate_hz": 15.0}, headers=AUTH).status_code
        == 200
    )
    # Reads are open on loopback.
    assert client.get("/api/motion").status_code == 200
    assert client.get("/api/camera/settings").json()["frame_rate_hz"] == 15.0


def test_reads_need_the_token_when_bound_beyond_loopback(tmp_path):
    with running_app(make_settings(tmp_path, host="0.0.0.0")) as c:
        assert c.get("/api/health").status_code == 200  # always answers
        assert c.get("/api/devices").status_code == 401
        assert c.get("/api/motion", headers=AUTH).status_code == 200


def test_out_of_limit_moves_never_reach_the_driver(settings, spy_devices):
    with running_app(settings, spy_devices) as c:
        bad = [
            {"yaw_deg": 171.0},
            {"pitch_deg": -60.5},
            {"rail_mm": 15000.0},
            {"roll_deg": 10.0, "pitch_deg": 90.0},  # one good axis, one bad: nothing moves
        ]
        for body in bad:
            r = c.post("/api/motion/move", json=body, headers=AUTH)
            assert r.status_code == 422, body
            assert "soft limits" in str(r.json()["detail"])
        for body in ({"tilt_deg": 1.0}, {}, {"yaw_deg": "ten"}, {"yaw_deg": None}):
            assert c.post("/api/motion/move", json=body, headers=AUTH).status_code == 422, body
        assert spy_devices.motion.calls == []
        assert c.post("/api/motion/move", json={"pitch_deg": 60.0}, headers=AUTH).status_code == 202
        assert spy_devices.motion.calls == [("move_to", {"pitch": 60.0})]


def test_camera_failure_degrades_and_recovers(settings, spy_devices):
    cam = spy_devices.camera
    with running_app(settings, spy_devices) as c:
        first = latest_pose(c)
        cam.failing.set()
        h = wait_for(
            lambda: (h := c.get("/api/health").json())["status"] == "degraded" and h,
            5.0,
            "degraded status",
        )
        assert h["camera"]["state"] == "degraded"
        assert "camera unplugged" in h["camera"]["last_error"]
        reads = cam.reads
        wait_for(lambda: cam.reads > reads + 3, 5.0, "retries")  # it keeps retrying
        assert c.get("/api/motion").status_code == 200  # the server stays up
        assert c.get("/api/devices").json()["camera"]["state"] == "degraded"
        cam.failing.clear()
        resumed = latest_pose(c, first["frame_index"] + 1)
        assert resumed["ok"]
        wait_for(lambda: c.get("/api/health").json()["status"] == "ok", 5.0, "recovery")


def test_restart_on_the_same_database_keeps_its_data(tmp_path):
    settings = make_settings(tmp_path / "data", api_token=None)
    square = {
        "name": "square-4",
        "reflectors": [
            {"id": i + 1, "position_mm": [x, y, z], "diameter_mm": 50.0}
            for i, (x, y, z) in enumerate(
                [(-200, -200, 0), (200, -200, 50), (200, 200, 0), (-200, 200, 100)]
            )
        ],
    }
    with running_app(settings) as c:
        token = (settings.data_dir / "api_token").read_text().strip()
        auth = {"Authorization": f"Bearer {token}"}
        assert c.post("/api/catalogs", json=square, headers=auth).status_code == 201
        assert c.post("/api/catalogs", json=square, headers=auth).status_code == 409
        new = {"frame_rate_hz": 12.5, "modulation_frequency_mhz": 8}
        r = c.put("/api/camera/settings", json=new, headers=auth)
        assert r.status_code == 200 and r.json()["unambiguous_range_mm"] == 18737.028625
        assert c.post("/api/catalogs/square-4/activate", headers=auth).json() == {
            "catalog": "square-4"
        }
    with running_app(Settings(**{**settings.model_dump(), "api_token": None})) as c:
        # The generated token survives the restart.
        assert (settings.data_dir / "api_token").read_text().strip() == token
        cats = {x["name"]: x for x in c.get("/api/catalogs").json()}
        assert cats["square-4"]["active"] and not cats["paper-target"]["active"]
        assert cats["square-4"]["reflectors"][3]["position_mm"] == [-200.0, 200.0, 100.0]
        s = c.get("/api/camera/settings").json()
        assert s["frame_rate_hz"] == 12.5 and s["modulation_frequency_mhz"] == 8.0
        assert c.get("/api/devices").json()["camera"]["catalog"] == "square-4"


def test_replay_camera_without_motion(tmp_path):
    from tofpose.workflows.simulation import simulate

    rec = tmp_path / "stability.h5"
    simulate("stability-697", 6, str(rec), seed=2, catalog_path=None, progress=False)
    settings = make_settings(tmp_path / "data", camera=f"replay:{rec}", motion="none")
    with running_app(settings) as c:
        p = latest_pose(c)
        assert p["catalog"] == "recording:paper-target"
        assert p["reference"]["position_error_mm"] < 15.0
        assert abs(p["z_mm"] - 697.0) < 30.0
        h = c.get("/api/health").json()
        assert h["motion"]["state"] == "absent" and h["camera"]["driver"] == "replay"
        r = c.post("/api/motion/move", json={"yaw_deg": 1.0}, headers=AUTH)
        assert r.status_code == 503 and "no motion system" in r.json()["detail"]


def test_live_pipeline_tracks_after_the_first_pose_unless_switched_off(tmp_path):
    with running_app(make_settings(tmp_path / "a")) as client:
        first = latest_pose(client)
        later = wait_for(
            lambda: (p := latest_pose(client, first["frame_index"]))["mode"] == "tracking" and p,
            10.0,
            "a tracked pose",
        )
        assert later["ok"] and later["n_matched"] >= 6
    with running_app(make_settings(tmp_path / "b", tracking=False)) as client:
        p = latest_pose(client, latest_pose(client)["frame_index"] + 2)
        assert p["mode"] == "acquisition"
