"""The server starts before the pipeline's kernels are compiled: frames stream at once,
/api/health says the kernels are compiling, no pose is claimed and no campaign counts a
frame until they are ready; then poses follow. The compile itself is replaced by a gate
the test opens (numba's cache is warm in the suite)."""

from __future__ import annotations

import threading

from backend.services import kernel_warmup
from tests.backend.conftest import AUTH, latest_pose, make_settings, running_app, wait_for


def test_frames_stream_while_the_kernels_compile_and_poses_follow(tmp_path, monkeypatch):
    gate = threading.Event()
    calls = []

    def slow_warm_up() -> float:
        calls.append(threading.current_thread().name)
        gate.wait(30.0)
        return 0.0

    monkeypatch.setattr(kernel_warmup, "warm_up", slow_warm_up)
    settings = make_settings(tmp_path / "data", kernels_in_background=True, sim_time_scale=5.0)
    with running_app(settings) as c:
        h = c.get("/api/health").json()
        assert h["pipeline"]["state"] == "compiling" and "compiling" in h["pipeline"]["detail"]
        assert h["status"] == "ok"  # compiling is not a fault
        first = latest_pose(c, ok=False)
        later = latest_pose(c, first["frame_index"] + 2, ok=False)  # frames keep coming
        assert not later["ok"] and later["reason"] == kernel_warmup.COMPILING_REASON
        assert c.get("/api/frames/latest/gray.png").status_code == 200  # the image is live
        body = {
            "name": "early", "frames_per_point": 3, "settle_s": 0.0,
            "setpoints": [{"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 13000}],
        }  # fmt: skip
        cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
        latest_pose(c, later["frame_index"] + 5, ok=False)
        assert c.get(f"/api/campaigns/{cid}").json()["n_done"] == 0  # nothing counted yet
        gate.set()
        wait_for(lambda: c.get("/api/health").json()["pipeline"]["state"] == "ready", 10.0,
                 "the kernels to be ready")  # fmt: skip
        pose = latest_pose(c, ok=True)
        assert 1500.0 < pose["z_mm"] < 2500.0  # the target 2 m in front of the camera
        wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "done", 30.0,
                 "the campaign to finish")  # fmt: skip
        rows = c.get(f"/api/campaigns/{cid}/measurements").json()["items"]
        assert len(rows) == 3 and all(r["ok"] for r in rows), rows
    assert calls == ["kernel-warmup"]  # in its own thread, once
