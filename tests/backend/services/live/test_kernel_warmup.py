"""The server starts before the pipeline's kernels are compiled: frames stream at once;
after the warm-up's first stage (the reference pipeline's few kernels) the poses come from
the reference implementation, and /api/health and /api/devices say so; when the kernels
are ready, from the compiled one. The compile itself is replaced by gates the test opens
(numba's cache is warm in the suite). And the first stage is all the reference pipeline
needs: after it, a fresh process's reference pipeline compiles nothing."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

from backend.services.live import kernel_warmup
from tests.backend.conftest import AUTH, latest_pose, make_settings, running_app, wait_for
from tofpose.core.geometry import rotation_angle_deg

ROOT = Path(__file__).resolve().parents[4]


def test_frames_stream_while_the_kernels_compile_and_poses_follow(tmp_path, monkeypatch):
    reference_gate, compiled_gate = threading.Event(), threading.Event()
    calls = []

    def gated(name, gate):
        def warm_up() -> float:
            calls.append((name, threading.current_thread().name))
            gate.wait(30.0)
            return 0.0

        return warm_up

    monkeypatch.setattr(kernel_warmup, "warm_up_reference", gated("reference", reference_gate))
    monkeypatch.setattr(kernel_warmup, "warm_up", gated("all", compiled_gate))
    settings = make_settings(tmp_path / "data", kernels_in_background=True, sim_time_scale=5.0)
    with running_app(settings) as c:
        acq = c.app.state.tofpose.acquisition
        # the first stage: frames without a pose
        h = c.get("/api/health").json()
        assert h["pipeline"]["state"] == "compiling" and h["pipeline"]["implementation"] is None
        assert h["pipeline"]["detail"] == kernel_warmup.COMPILING_REASON
        assert h["status"] == "ok"  # compiling is not a fault
        first = latest_pose(c, ok=False)
        later = latest_pose(c, first["frame_index"] + 2, ok=False)  # frames keep coming
        assert not later["ok"] and later["reason"] == kernel_warmup.COMPILING_REASON
        assert c.get("/api/frames/latest/gray.png").status_code == 200  # the image is live
        # the reference implementation's poses while the rest compiles
        reference_gate.set()
        pose = latest_pose(c, later["frame_index"], ok=True)
        sample = acq.latest
        assert sample.implementation == "reference" and sample.result.ok
        T = sample.frame.T_camera_target_exact  # the pose the simulator rendered, 2 m away
        np.testing.assert_allclose(sample.result.t_mm, T.t_mm, atol=3.0)
        assert rotation_angle_deg(sample.result.R, T.R) < 0.2
        assert 1500.0 < pose["z_mm"] < 2500.0
        for path in ("/api/health", "/api/devices"):
            p = c.get(path).json()["pipeline"]
            assert (p["state"], p["implementation"]) == ("compiling", "reference"), path
            assert p["detail"] == kernel_warmup.REFERENCE_DETAIL
        # a campaign counts the reference poses (they are the compiled ones to ~0.01 mm)
        body = {
            "name": "early",
            "frames_per_point": 3,
            "settle_s": 0.0,
            "setpoints": [{"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 13000}],
        }
        cid = c.post("/api/campaigns", json=body, headers=AUTH).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start", headers=AUTH).status_code == 200
        wait_for(
            lambda: c.get(f"/api/campaigns/{cid}").json()["status"] == "done",
            30.0,
            "the campaign to finish",
        )
        rows = c.get(f"/api/campaigns/{cid}/measurements").json()["items"]
        assert len(rows) == 3 and all(r["ok"] for r in rows), rows
        assert acq.kernels.state == "compiling"
        # the kernels ready: the compiled pipeline from the next frame on
        compiled_gate.set()
        wait_for(
            lambda: c.get("/api/health").json()["pipeline"]["implementation"] == "compiled",
            10.0,
            "the compiled pipeline",
        )
        p = c.get("/api/devices").json()["pipeline"]
        assert (p["state"], p["implementation"], p["detail"]) == ("ready", "compiled", "")
        pose = latest_pose(c, pose["frame_index"], ok=True)
        assert acq.latest.implementation == "compiled"
        assert 1500.0 < pose["z_mm"] < 2500.0
    assert calls == [("reference", "kernel-warmup"), ("all", "kernel-warmup")]  # once each


#: a fresh interpreter: the first stage, then the reference pipeline (acquisition and
#: tracking at 2 m and 5.7 m, float32 and float64 distances), every request to numba's
#: dispatchers (a compile, or a load from its cache) recorded
FRESH_PROCESS = """
import numpy as np
from numba.core import dispatcher
from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.config import PipelineConfig, TrackingConfig
from tofpose.pipeline import PosePipeline
from tofpose.warmup import warm_up_reference

frames = [render(facing_pose(d + 3.0 * k, 5.0, -8.0, 20.0), seed=40 + k)
          for d in (2000.0, 5700.0) for k in range(4)]
requested = []
compile_for_args = dispatcher.Dispatcher._compile_for_args
def spy(self, *args, **kwargs):
    requested.append(self.py_func.__name__)
    return compile_for_args(self, *args, **kwargs)
dispatcher.Dispatcher._compile_for_args = spy
warm_up_reference()
print("stage 1:", *sorted(set(requested)))
requested.clear()
pipe = PosePipeline(CameraModel(), paper_target(),
                    PipelineConfig(tracking=TrackingConfig(enabled=True)),
                    implementation="reference")
modes = set()
for f in frames:
    for distance in (f.distance_mm, f.distance_mm.astype(np.float64)):
        r = pipe.process(f.gray, distance)
        assert r.ok, r.reason
        modes.add(r.mode)
print("modes:", *sorted(modes))
print("reference pipeline:", *sorted(set(requested)))
"""


def test_after_the_first_stage_the_reference_pipeline_compiles_nothing():
    """In a fresh process (nothing compiled or loaded yet), ``warm_up_reference`` asks
    numba for the frame check's and the history's kernels, and the reference pipeline
    then asks it for none: it never compiles in the live loop's thread."""
    out = subprocess.run(
        [sys.executable, "-c", FRESH_PROCESS], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    stage1 = set(out[0].split()[2:])
    assert {"checked_frame", "clean_distance", "pixel_mask"} <= stage1, out
    assert out[1].split()[1:] == ["acquisition", "tracking"]
    assert out[2] == "reference pipeline:", out
