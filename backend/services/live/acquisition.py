"""The acquisition loop: one thread owns the camera, runs ``PosePipeline`` on every frame
pair, keeps the latest sample and a bounded history, and publishes to the hub.

A camera error or timeout marks the device degraded and is retried with exponential
backoff; nothing a driver or a subscriber does can stop the loop. Commands for the camera
(settings changes) are queued to the loop so that only its thread touches the device.

While the pipeline's kernels compile at server start (``KernelWarmup``), the loop measures
with the reference implementation (``PosePipeline(..., implementation="reference")``:
every stage in NumPy/SciPy, the compiled poses to ~0.01 mm and ~0.0002 deg), from the
moment the warm-up's first stage has compiled the few kernels it still calls (about 1 s;
before that a frame streams without a pose). When the kernels are ready the next frame
goes through a compiled pipeline (``_pipeline_for_frame``); no frame goes without a pose
for it. The new pipeline starts without multi-frame history, as after a discontinuity
(its first frame is an acquisition, a full search: one frame of persistence and tracking
state is all that is lost, and the two implementations' histories are not mixed); the
relative-state filter goes on across the switch (the two implementations' poses differ
far less than their noise, so its rates and velocity need no restart).

A frame is read only when the loop is free: drivers pace their frames without a backlog
(``backend.drivers.pacing.FramePacer``; a real camera is asked for each image), so a
pipeline slower than the camera measures the newest frame each time and lowers the
delivered frame rate while it is slower; nothing queues. The reference pipeline takes
~60 ms a frame on 2 cores, ~85 ms (median; 95th percentile ~190 ms) while the other core
compiles (``bench/first_run.py``): the camera delivers ~7.6 of its 10 frames/s meanwhile.

Every frame is stamped on the host's monotonic clock (``backend.services.live.latency``):
its capture (the driver's, else its arrival), its arrival from the driver, and when its
pose was ready; ``latency`` (``LiveStatistics``) keeps them with the frames the camera
and the pipeline dropped, and the live WebSocket adds when each client was sent it.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from backend.drivers.base import CameraDriver, CameraFrame
from backend.services.live.hub import LiveHub
from backend.services.live.kernel_warmup import COMPILING_REASON, KernelWarmup
from backend.services.live.latency import FrameStamps, LiveStatistics
from backend.services.live.live_reference import LiveReference
from tofpose.config import config_for_camera
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.lab.relative_state import RelativeState, RelativeStateConfig, RelativeStateFilter
from tofpose.pipeline import PipelineConfig, PosePipeline, PoseResult
from tofpose.stages.extraction.extraction import FrameError

log = logging.getLogger(__name__)


Implementation = Literal["reference", "compiled"]
"""The pipeline implementations the live loop runs (``tofpose.arithmetic.IMPLEMENTATIONS``)."""


def _implementation(pipeline: PosePipeline | None) -> Implementation | None:
    """The implementation ``pipeline`` runs (``PosePipeline`` names it as text), None
    without a pipeline."""
    if pipeline is None:
        return None
    return "reference" if pipeline.implementation == "reference" else "compiled"


@dataclass
class LiveSample:
    """One processed frame: the frame pair, its result and when things happened.

    captured_unix_s : wall-clock time the frame arrived from the driver.
    processed_unix_s : wall-clock time the pipeline finished.
    stamps : the frame's capture, arrival and pose-ready stamps (host monotonic ns,
        ``FrameStamps``); None for a sample not made by the loop.
    camera_gap : frames the camera lost just before this one (its counter's gap).
    pipeline_skipped : frames the camera's rate offered while the loop was busy with
        the previous one (skipped, never measured).
    measured : False for a frame no pipeline saw (the first second of a first start,
        before the warm-up's first stage): shown live, never counted by a campaign.
    implementation : the pipeline implementation that measured it: "reference" while
        the kernels compile at server start, "compiled" after; None when not measured.
    reference : the lab reference the live error of this frame is measured against.
    state : the relative-state filter's state at the frame's time (pose, rates,
        velocity and their covariance; ``tofpose.lab.relative_state``), None before its
        first pose.
    camera_model : the camera model the frame was taken and measured with (its
        modulation frequency: where its distances wrap, their noise); None for a sample
        not made by the loop (a recording then takes the camera's model now).
    cache : serialised forms (JSON, PNG) computed once and shared by all consumers.
    """

    frame: CameraFrame
    result: PoseResult
    catalog_name: str
    captured_unix_s: float
    processed_unix_s: float
    measured: bool = True
    implementation: Implementation | None = "compiled"
    reference: LiveReference = field(default_factory=LiveReference)
    state: RelativeState | None = None
    camera_model: CameraModel | None = None
    cache: dict[str, Any] = field(default_factory=dict)
    stamps: FrameStamps | None = None
    camera_gap: int = 0
    pipeline_skipped: int = 0

    def cached(self, key: str, make: Callable[[], Any]) -> Any:
        """Serialised forms of this sample (JSON, the raw binary frame). PNGs live in the
        bounded ``ImageRenderer`` cache; the history keeps samples without this cache."""
        if key not in self.cache:
            self.cache[key] = make()
        return self.cache[key]

    @property
    def has_images(self) -> bool:
        return self.frame.gray.size > 0

    def without_images(self) -> LiveSample:
        """The same result with the frame's images dropped (shape (0, 0)): what the
        history keeps, so that its memory is the results', not 450 kB of pixels each."""
        frame = replace(self.frame, gray=_NO_GRAY, distance_mm=_NO_DISTANCE)
        return replace(self, frame=frame, cache={})


_NO_GRAY = np.zeros((0, 0), np.uint16)
_NO_DISTANCE = np.zeros((0, 0), np.float32)


@dataclass
class DeviceHealth:
    """State of a device as the server sees it: ``starting``, ``ok``, ``degraded``,
    ``stopped``."""

    state: str = "starting"
    last_error: str | None = None
    last_error_unix_s: float | None = None
    error_count: int = 0
    consecutive_failures: int = 0

    def record_failure(self, message: str) -> None:
        self.state = "degraded"
        self.last_error = message
        self.last_error_unix_s = time.time()
        self.error_count += 1
        self.consecutive_failures += 1

    def record_ok(self) -> None:
        self.state = "ok"
        self.consecutive_failures = 0


class AcquisitionService:
    """Runs the live loop in a daemon thread; see the module docstring."""

    def __init__(
        self,
        camera: CameraDriver,
        catalog: Catalog,
        catalog_name: str,
        hub: LiveHub,
        *,
        history_size: int = 600,
        timeout_s: float = 2.0,
        backoff_s: tuple[float, float] = (0.05, 2.0),
        pipeline_config: PipelineConfig | None = None,
        kernels: KernelWarmup | None = None,
        state_config: RelativeStateConfig | None = None,
        latency: LiveStatistics | None = None,
    ) -> None:
        self.camera = camera
        #: the frames' stamps and drops over a sliding window (``latency.LiveStatistics``)
        self.latency = latency or LiveStatistics()
        self.hub = hub
        self.timeout_s = timeout_s
        self.backoff_s = backoff_s
        self.health = DeviceHealth()
        # the pixel- and count-valued settings follow the camera (its frame size and
        # count scale; saturation and range the pipeline takes from the model itself)
        m = camera.model
        self._config = config_for_camera(
            pipeline_config or PipelineConfig(),
            width=m.width,
            height=m.height,
            count_scale=m.count_scale,
        )
        self.kernels = kernels  # None: the kernels are ready (or compile on first use)
        self.reference = LiveReference()  # nominal until a calibration is selected
        self._catalog_name = catalog_name
        first = self._live_implementation() or "reference"  # (None: reference soon)
        self._pipeline = self._new_pipeline(catalog, first)
        #: the relative state (rates, velocity) from the poses, on the loop's thread
        state_config = state_config or RelativeStateConfig.constant_acceleration()
        self._filter = RelativeStateFilter(state_config)
        self._history: deque[LiveSample] = deque(maxlen=history_size)
        self._latest: LiveSample | None = None
        self._commands: queue.Queue[tuple[Callable[[], Any], Future]] = queue.Queue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._arrivals: deque[float] = deque(maxlen=30)
        self.frames_processed = 0

    # -- lifecycle ----------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="acquisition", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self.health.state = "stopped"
        while not self._commands.empty():
            _, fut = self._commands.get_nowait()
            fut.set_exception(RuntimeError("acquisition stopped"))

    # -- what others read ---------------------------------------------------------------
    @property
    def latest(self) -> LiveSample | None:
        return self._latest

    @property
    def pipeline_config(self) -> PipelineConfig:
        """The live pipeline's settings, scaled to the camera (``config_for_camera``)."""
        return self._config

    @property
    def catalog_name(self) -> str:
        return self._catalog_name

    @property
    def catalog(self) -> Catalog:
        return self._pipeline.catalog

    @property
    def implementation(self) -> Implementation | None:
        """The pipeline implementation that measured the latest frame; before a frame
        was measured, the one that will measure the next (None: none can yet)."""
        latest = self._latest
        if latest is not None and latest.measured:
            return latest.implementation
        return self._live_implementation()

    def _live_implementation(self) -> Implementation | None:
        """The implementation for the next frame: "compiled" once the kernels are ready
        (or when nothing warms them up: ``kernels`` None), "reference" while they compile
        and after a failed warm-up (rather than compile them in the loop's thread, which
        would stop it for a minute), None during the warm-up's first stage."""
        k = self.kernels
        if k is None or k.state == "ready":
            return "compiled"
        return "reference" if k.reference_ready.is_set() else None

    def _pipeline_for_frame(self) -> PosePipeline | None:
        """The pipeline for the next frame (module docstring), switched to the compiled
        implementation when the kernels have become ready; None: no pipeline yet."""
        wanted = self._live_implementation()
        if wanted is not None and wanted != self._pipeline.implementation:
            self._pipeline = self._new_pipeline(self._pipeline.catalog, wanted)
            log.info("live poses now from the %s pipeline", wanted)
        elif self.camera.model is not self._pipeline.camera:
            # the camera's settings changed its model (a modulation frequency: where the
            # distances wrap, their noise): measure with the model the frames come from
            self._pipeline = self._new_pipeline(
                self._pipeline.catalog, self._pipeline.implementation
            )
        return None if wanted is None else self._pipeline

    def _new_pipeline(self, catalog: Catalog, implementation: str) -> PosePipeline:
        """A pipeline of the camera's model now, with the loop's settings; the reference
        implementation (while the kernels compile) without the pixel-level fit, whose
        NumPy form takes seconds a frame: its poses say so (``pixel_fit`` empty)."""
        config = self._config
        if implementation == "reference" and config.pixel_fit.enabled:
            config = replace(config, pixel_fit=replace(config.pixel_fit, enabled=False))
        return PosePipeline(self.camera.model, catalog, config, implementation=implementation)

    def history(self, n: int) -> list[LiveSample]:
        """The last ``n`` results, oldest first, without their images."""
        items = list(self._history)
        return items[-n:] if n > 0 else []

    @property
    def frame_rate_hz(self) -> float:
        """Delivered frame rate over the last few frames (0 if unknown)."""
        t = list(self._arrivals)
        if len(t) < 2 or t[-1] <= t[0]:
            return 0.0
        return (len(t) - 1) / (t[-1] - t[0])

    # -- commands run on the loop's thread ----------------------------------------------
    def submit(self, fn: Callable[[], Any]) -> Future:
        """Run ``fn`` on the acquisition thread between frames; returns a Future."""
        fut: Future = Future()
        if self._stop.is_set():
            fut.set_exception(RuntimeError("acquisition stopped"))
        else:
            self._commands.put((fn, fut))
        return fut

    def set_catalog(self, name: str, catalog: Catalog) -> Future:
        def swap() -> None:
            self._pipeline = self._new_pipeline(catalog, self._pipeline.implementation)
            self._filter.reset()  # another target: its motion starts again
            self._catalog_name = name

        return self.submit(swap)

    def _run_commands(self) -> None:
        while True:
            try:
                fn, fut = self._commands.get_nowait()
            except queue.Empty:
                return
            if fut.set_running_or_notify_cancel():
                try:
                    fut.set_result(fn())
                except Exception as exc:  # handed to the caller
                    fut.set_exception(exc)

    # -- the loop -----------------------------------------------------------------------
    def _run(self) -> None:
        backoff = self.backoff_s[0]
        while not self._stop.is_set():
            self._run_commands()
            try:
                frame = self.camera.read(self.timeout_s)
            except Exception as exc:
                if self._stop.is_set():
                    break
                kind = "timed out" if isinstance(exc, TimeoutError) else "failed"
                self.health.record_failure(f"camera {kind}: {exc}")
                log.warning("camera %s (%s); retrying in %.2f s", kind, exc, backoff)
                self._stop.wait(backoff)
                backoff = min(2.0 * backoff, self.backoff_s[1])
                continue
            # the model the frame was taken with (settings change only between reads, on
            # this thread; the pipeline below is rebuilt to it)
            model = self.camera.model
            arrival_ns = time.monotonic_ns()
            captured = time.time()
            self._arrivals.append(arrival_ns / 1e9)
            if frame.meta.get("discontinuity"):
                self._pipeline.reset()
                self._filter.reset()
            pipeline = self._pipeline_for_frame()
            measured = pipeline is not None
            try:
                if pipeline is not None:
                    result = pipeline.process(frame.gray, frame.distance_mm, frame.time_s)
                else:
                    _check_shapes(frame, self.camera.model.shape)  # no kernel call yet
                    result = PoseResult(False, COMPILING_REASON, frame.time_s)
            except FrameError as exc:
                self.health.record_failure(f"malformed frame from the camera: {exc}")
                continue
            except Exception as exc:  # a pipeline bug must not stop the live loop
                log.exception("pipeline failed on frame %d", frame.index)
                result = PoseResult(False, f"pipeline error: {exc}", frame.time_s)
            backoff = self.backoff_s[0]
            self.health.record_ok()
            state = self._relative_state(result, frame.time_s) if measured else None
            stamps = FrameStamps(
                capture_ns=frame.capture_ns if frame.capture_ns is not None else arrival_ns,
                arrival_ns=arrival_ns,
                pose_ready_ns=time.monotonic_ns(),
                capture_from_device=frame.capture_ns is not None,
            )
            gap, skipped = self.latency.record_frame(
                stamps, sequence=frame.sequence, slots_skipped=frame.slots_skipped
            )
            sample = LiveSample(
                frame,
                result,
                self._catalog_name,
                captured,
                time.time(),
                measured=measured,
                implementation=_implementation(pipeline),
                reference=self.reference,
                state=state,
                camera_model=model,
                stamps=stamps,
                camera_gap=gap,
                pipeline_skipped=skipped,
            )
            self._latest = sample
            self._history.append(sample.without_images())
            self.frames_processed += 1
            try:
                self.hub.publish(sample)
            except Exception:
                log.exception("publishing frame %d failed", frame.index)

    def _relative_state(self, result: PoseResult, time_s: float) -> RelativeState | None:
        """The filter stepped with this frame (``RelativeStateFilter.step``); a filter
        failure (a pose it cannot take) restarts it and never stops the loop."""
        pose = (result.R, result.t_mm, result.covariance) if result.ok else (None,) * 3
        try:
            return self._filter.step(time_s, *pose)
        except Exception:
            log.exception("relative-state filter failed at t = %.3f s; restarting it", time_s)
            self._filter.reset()
            return None


def _check_shapes(frame: CameraFrame, shape: tuple[int, int]) -> None:
    """The part of the pipeline's frame check that needs no compiled kernel."""
    for name, image in (("gray", frame.gray), ("distance", frame.distance_mm)):
        if np.shape(image) != shape:
            raise FrameError(f"{name} image has shape {np.shape(image)}, camera expects {shape}")


def frame_point_cloud_mm(sample: LiveSample, camera_model) -> tuple[np.ndarray, list[int | None]]:
    """Camera-frame 3-D points of every detected blob, matched then unmatched.

    Returns (points_mm (N, 3), catalog_ids (N,)) with ``None`` ids for unmatched blobs.
    Unmatched blobs without a valid distance (no finite 3-D point) are left out.
    """
    res = sample.result
    pts = [np.asarray(m.point_mm, float) for m in res.matched]
    ids: list[int | None] = [m.catalog_id for m in res.matched]
    if res.unmatched:
        uvd = np.asarray(res.unmatched, float)
        uvd = uvd[np.isfinite(uvd).all(axis=1)]
        pts.extend(camera_model.back_project(uvd[:, :2], uvd[:, 2]))
        ids += [None] * len(uvd)
    return np.asarray(pts, float).reshape(-1, 3), ids
