"""The acquisition loop with a scripted camera: results, history, degradation, commands,
and the reference implementation's poses while the kernels compile."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections import Counter

import numpy as np
import pytest

from backend.drivers.base import CameraFrame, CameraSettings
from backend.services.live import kernel_warmup
from backend.services.live.acquisition import AcquisitionService, frame_point_cloud_mm
from backend.services.live.hub import LiveHub
from backend.services.live.kernel_warmup import COMPILING_REASON, KernelWarmup
from tests.backend.conftest import wait_for
from tests.conftest import facing_pose, render
from tofpose.arithmetic import COMPILED
from tofpose.config import PipelineConfig, TrackingConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_angle_deg


class ScriptedCamera:
    """Serves one pre-rendered frame pair at ~200 Hz; can fail, hang or send junk."""

    name = "scripted"

    def __init__(self) -> None:
        self.model = CameraModel()
        self.T = facing_pose(1500.0, yaw_deg=5.0)
        f = render(self.T, seed=1)
        self.gray, self.dist = f.gray, f.distance_mm
        self.mode = "ok"
        self.n = 0
        self.settings = CameraSettings()
        self.thread_names: set[str] = set()

    def read(self, timeout_s):
        self.thread_names.add(threading.current_thread().name)
        time.sleep(0.005)
        if self.mode == "raise":
            raise OSError("link down")
        if self.mode == "hang":
            time.sleep(timeout_s)
            raise TimeoutError(f"no frame within {timeout_s} s")
        self.n += 1
        gray = self.gray[:10] if self.mode == "junk" else self.gray
        return CameraFrame(gray, self.dist, 0.005 * self.n, self.n, T_camera_target_exact=self.T)

    def get_settings(self):
        return self.settings

    def apply_settings(self, s):
        self.thread_names.add(threading.current_thread().name)
        self.settings = s
        return s

    def close(self):
        pass


@pytest.fixture
def service():
    cam = ScriptedCamera()
    hub = LiveHub()
    svc = AcquisitionService(
        cam,
        paper_target(),
        "paper-target",
        hub,
        history_size=20,
        timeout_s=0.05,
        backoff_s=(0.01, 0.04),
    )
    svc.start()
    yield svc, cam, hub
    svc.stop()


def test_results_history_and_publication(service):
    svc, cam, hub = service
    sub = hub.subscribe(maxsize=100)
    wait_for(lambda: svc.frames_processed >= 25, what="25 frames")
    s = svc.latest
    assert s.result.ok and s.result.n_matched == 8
    np.testing.assert_allclose(s.result.t_mm, cam.T.t_mm, atol=3.0)
    assert len(svc.history(100)) == 20  # bounded
    idx = [x.frame.index for x in svc.history(5)]
    assert idx == sorted(idx) and len(idx) == 5
    assert sub.get(1.0).frame.index >= 1
    assert svc.health.state == "ok"
    # The history keeps results, not pixels; the latest frame and subscribers keep both.
    assert s.has_images and sub.get(1.0).has_images
    past = svc.history(20)
    assert not any(x.has_images for x in past)
    assert all(x.result.ok and x.result.n_matched == 8 for x in past)
    pts, ids = frame_point_cloud_mm(s, cam.model)
    assert pts.shape == (8 + len(s.result.unmatched), 3) and len(ids) == len(pts)


@pytest.mark.parametrize(
    ("mode", "needle"), [("raise", "link down"), ("hang", "timed out"), ("junk", "malformed frame")]
)
def test_camera_trouble_degrades_then_recovers(service, mode, needle):
    svc, cam, _ = service
    wait_for(lambda: svc.frames_processed > 2, what="first frames")
    cam.mode = mode
    wait_for(lambda: svc.health.state == "degraded", what="degraded")
    assert needle in svc.health.last_error
    errors = svc.health.error_count
    wait_for(lambda: svc.health.error_count > errors + 2, what="retries")
    cam.mode = "ok"
    n = svc.frames_processed
    wait_for(lambda: svc.frames_processed > n + 3 and svc.health.state == "ok", what="recovery")
    assert svc.health.consecutive_failures == 0


def test_a_stuck_subscriber_does_not_slow_the_loop(service):
    svc, _, hub = service
    hub.subscribe(maxsize=1)  # never read
    n0 = svc.frames_processed
    wait_for(lambda: svc.frames_processed > n0 + 40, what="40 frames")
    assert hub.subscriptions()[0].dropped > 30


def test_commands_run_on_the_acquisition_thread(service):
    svc, cam, _ = service
    fut = svc.submit(lambda: cam.apply_settings(CameraSettings(frame_rate_hz=7.0)))
    assert fut.result(2.0).frame_rate_hz == 7.0
    assert cam.thread_names == {"acquisition"}
    failing = svc.submit(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        failing.result(2.0)
    assert svc.health.state == "ok"


def test_catalog_swap_takes_effect(service):
    from tofpose.core.catalog import Catalog

    svc, _, _ = service
    sub4 = Catalog("first-four", paper_target().reflectors[:4])
    svc.set_catalog("first-four", sub4).result(2.0)
    n = svc.frames_processed
    wait_for(lambda: svc.frames_processed > n + 2, what="frames with the new catalog")
    s = svc.latest
    assert s.catalog_name == "first-four"
    assert {m.catalog_id for m in s.result.matched} <= {1, 2, 3, 4}


class TurningCamera(ScriptedCamera):
    """Frames of a target turning at ``rate_deg_s`` about the camera's y axis (a yaw
    slew of the table), rendered at 10 Hz frame time; after the last one the camera
    waits (no frame), as a camera whose target left the view would."""

    def __init__(self, rate_deg_s: float, n: int = 40) -> None:
        super().__init__()
        from scipy.spatial.transform import Rotation

        from tofpose.core.geometry import RigidTransform

        T0 = facing_pose(3000.0, 2.0, -3.0, 5.0)
        self.poses, self.frames = [], []
        for k in range(n):
            R = Rotation.from_rotvec([0.0, np.radians(rate_deg_s) * 0.1 * k, 0.0]).as_matrix()
            T = RigidTransform(R @ T0.R, T0.t_mm)
            f = render(T, seed=50 + k)
            self.poses.append(T)
            self.frames.append((f.gray, f.distance_mm))

    def read(self, timeout_s):
        if self.n >= len(self.frames):
            time.sleep(timeout_s)
            raise TimeoutError("no more frames")
        time.sleep(0.005)
        gray, dist = self.frames[self.n]
        self.n += 1
        return CameraFrame(
            gray, dist, 0.1 * (self.n - 1), self.n, T_camera_target_exact=self.poses[self.n - 1]
        )


@pytest.mark.parametrize("rate_deg_s", [0.0, 6.0])
def test_the_live_loop_gives_the_targets_angular_rate(rate_deg_s):
    """The loop runs the relative-state filter on its poses: after 2 s every frame's
    rate is within its sigmas of the truth (zero for a static target, 6 deg/s about the
    camera's y axis for a turning one), the mean over the last 2 s within 15 %, and every
    frame of the history keeps its state."""
    cam = TurningCamera(rate_deg_s)
    svc = AcquisitionService(
        cam,
        paper_target(),
        "paper-target",
        LiveHub(),
        history_size=100,
        timeout_s=0.05,
        backoff_s=(0.01, 0.04),
    )
    svc.start()
    try:
        wait_for(lambda: svc.frames_processed >= len(cam.frames), timeout_s=60, what="all frames")
    finally:
        svc.stop()
    past = svc.history(100)
    assert past[0].state is not None and past[0].state.status == "initialised"
    assert all(s.state is not None for s in past)
    truth = np.array([0.0, rate_deg_s, 0.0])
    late = [s.state for s in past[-20:]]  # after 2 s
    assert all(st.status == "updated" for st in late)
    for st in late:  # each within its own sigmas (the server's filter follows a table
        # that accelerates at tens of deg/s^2, so its rate is noisy: ~2.5 deg/s here)
        w, sigma = st.angular_rate_deg_s, st.angular_rate_sigma_deg_s
        assert np.all(np.abs(w - truth) < 3.5 * sigma), (w, sigma)
        assert np.all(sigma < 4.0)
    mean = np.mean([st.angular_rate_deg_s for st in late], axis=0)
    assert np.all(np.abs(mean - truth) < 0.15 * rate_deg_s + 0.5), mean


@pytest.fixture
def compiled_calls():
    """Counts the calls of every function of the compiled arithmetic
    (``tofpose.arithmetic.COMPILED``: what a compiled pipeline runs, each stage's kernels),
    by ``stage.function``; restored afterwards."""
    calls: Counter[str] = Counter()
    saved: list[tuple[object, str, object]] = []

    def counted(name, fn):
        def call(*args, **kwargs):
            calls[name] += 1
            return fn(*args, **kwargs)

        return call

    for stage in dataclasses.fields(COMPILED):
        if stage.name == "name":
            continue
        record = getattr(COMPILED, stage.name)
        for f in dataclasses.fields(record):
            fn = getattr(record, f.name)
            if callable(fn):
                saved.append((record, f.name, fn))
                object.__setattr__(record, f.name, counted(f"{stage.name}.{f.name}", fn))
    try:
        yield calls
    finally:
        for record, name, fn in saved:
            object.__setattr__(record, name, fn)


def gated_warm_up(monkeypatch) -> tuple[KernelWarmup, threading.Event, threading.Event]:
    """A ``KernelWarmup`` whose two stages (the reference pipeline's kernels, then all)
    each wait for a gate the test opens (numba's cache is warm in the suite)."""
    gates = threading.Event(), threading.Event()
    for name, gate in zip(("warm_up_reference", "warm_up"), gates, strict=True):
        monkeypatch.setattr(kernel_warmup, name, lambda gate=gate: float(gate.wait(30.0)))
    kernels = KernelWarmup()
    kernels.start()
    return kernels, *gates


def assert_pose_near_truth(sample, T) -> None:
    """The sample's pose is that of the rendered frame (1.5 m, 8 reflectors)."""
    r = sample.result
    assert r.ok and r.n_matched == 8, r.reason
    np.testing.assert_allclose(r.t_mm, T.t_mm, atol=3.0)
    assert rotation_angle_deg(r.R, T.R) < 0.2


def test_the_reference_pipeline_measures_while_the_kernels_compile(monkeypatch, compiled_calls):
    """Before the warm-up's first stage, frames stream without a pose; then the reference
    implementation gives them (no compiled function called) until the kernels are ready;
    then the compiled one, from the very next frame: every measured frame has a pose,
    the first compiled one a full acquisition, and the relative-state filter goes on."""
    kernels, reference_gate, compiled_gate = gated_warm_up(monkeypatch)
    cam = ScriptedCamera()
    hub = LiveHub()
    sub = hub.subscribe(maxsize=10_000)  # every frame, in order
    config = PipelineConfig(tracking=TrackingConfig(enabled=True))  # as the server's
    svc = AcquisitionService(
        cam,
        paper_target(),
        "paper-target",
        hub,
        timeout_s=0.05,
        backoff_s=(0.01, 0.04),
        pipeline_config=config,
        kernels=kernels,
    )
    assert svc.implementation is None
    svc.start()
    try:
        wait_for(lambda: svc.frames_processed >= 3, what="frames before the first stage")
        s = svc.latest
        assert not s.measured and s.implementation is None
        assert not s.result.ok and s.result.reason == COMPILING_REASON
        reference_gate.set()
        wait_for(lambda: svc.implementation == "reference", what="a reference pose")
        n = svc.frames_processed
        wait_for(lambda: svc.frames_processed >= n + 5, what="5 reference poses")
        assert kernels.state == "compiling"
        s = svc.latest
        assert s.measured and s.implementation == "reference"
        assert_pose_near_truth(s, cam.T)
        assert sum(compiled_calls.values()) == 0, compiled_calls
        compiled_gate.set()
        wait_for(lambda: svc.implementation == "compiled", what="a compiled pose")
        n = svc.frames_processed
        wait_for(lambda: svc.frames_processed >= n + 3, what="3 compiled poses")
    finally:
        svc.stop()
    samples = []
    while (s := sub.get(0.0)) is not None:
        samples.append(s)
    kinds = [s.implementation for s in samples]
    first_ref, first_compiled = kinds.index("reference"), kinds.index("compiled")
    assert set(kinds[:first_ref]) == {None}
    assert set(kinds[first_ref:first_compiled]) == {"reference"}
    assert set(kinds[first_compiled:]) == {"compiled"}
    assert sum(compiled_calls.values()) > 0 and compiled_calls["extraction.frame_levels"] > 0
    measured = samples[first_ref:]
    assert all(s.measured and s.result.ok for s in measured)  # no frame without a pose
    assert_pose_near_truth(samples[first_compiled - 1], cam.T)
    assert_pose_near_truth(samples[first_compiled], cam.T)
    # the reference pipeline tracked; the compiled one starts with a fresh history: a
    # full acquisition, then tracking from its pose
    assert [s.result.mode for s in samples[first_compiled : first_compiled + 2]] == [
        "acquisition",
        "tracking",
    ]
    assert "tracking" in {s.result.mode for s in samples[first_ref:first_compiled]}
    # the filter went on across the switch: initialised once, at the first reference pose
    statuses = [s.state.status for s in measured]
    assert statuses[0] == "initialised" and "initialised" not in statuses[1:]


def test_a_failed_warm_up_keeps_the_reference_pipeline(monkeypatch, compiled_calls):
    """A warm-up that fails after its first stage leaves the loop on the reference
    implementation (compiling in the loop's thread would stop it for a minute)."""

    def failing() -> float:
        raise RuntimeError("no LLVM today")

    monkeypatch.setattr(kernel_warmup, "warm_up", failing)
    kernels = KernelWarmup()
    kernels.run()
    assert kernels.state == "failed" and "no LLVM today" in kernels.error
    cam = ScriptedCamera()
    svc = AcquisitionService(
        cam,
        paper_target(),
        "paper-target",
        LiveHub(),
        timeout_s=0.05,
        backoff_s=(0.01, 0.04),
        kernels=kernels,
    )
    svc.start()
    try:
        wait_for(lambda: svc.frames_processed >= 3, what="3 poses")
    finally:
        svc.stop()
    assert svc.implementation == "reference"
    assert_pose_near_truth(svc.latest, cam.T)
    assert sum(compiled_calls.values()) == 0


def test_the_reference_pipeline_runs_without_the_pixel_fit_and_the_compiled_one_with_it():
    """With the pixel fit asked for (``TOFPOSE_PIXEL_FIT``), the pipelines the loop makes
    (first, on a switch of implementation, a new camera model or catalog) keep it, but the
    reference implementation (while the kernels compile) measures without it: its NumPy
    form takes seconds a frame."""
    cfg = PipelineConfig(pixel_fit=dataclasses.replace(PipelineConfig().pixel_fit, enabled=True))
    svc = AcquisitionService(
        ScriptedCamera(), paper_target(), "paper-target", LiveHub(), pipeline_config=cfg
    )
    compiled = svc._new_pipeline(paper_target(), "compiled")
    reference = svc._new_pipeline(paper_target(), "reference")
    assert compiled.config.pixel_fit.enabled and compiled.implementation == "compiled"
    assert not reference.config.pixel_fit.enabled and reference.implementation == "reference"
    assert svc._pipeline.config.pixel_fit.enabled  # kernels ready: the compiled one, with it
    # everything else is the loop's configuration
    assert dataclasses.replace(reference.config, pixel_fit=cfg.pixel_fit) == compiled.config
