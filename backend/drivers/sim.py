"""Simulated camera and turntable sharing one simulated lab (tofpose.sim).

The lab: the target stands ``target_distance_mm`` from the turntable centre; the camera
rides the turntable on a rail that moves it towards the target (docs/architecture.md
§6). Time is the wall clock since the world was made, so the turntable moves in real
time and the camera sees what it does.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np

from backend.drivers.base import (
    AxisLimits,
    CameraFrame,
    CameraLimits,
    CameraSettings,
    MotionStatus,
    ProfileStatus,
)
from backend.drivers.pacing import FramePacer
from tofpose import __version__
from tofpose.core.catalog import Catalog, paper_target
from tofpose.lab.motion_profile import MotionProfile
from tofpose.sim.bench import LabGeometry, SimulatedBench
from tofpose.sim.render import render_frame
from tofpose.sim.scenarios import paper_mount_error
from tofpose.sim.scene import TargetScene
from tofpose.sim.turntable import Turntable


class SimWorld:
    """The simulated lab: one bench, one clock, one lock for the turntable state."""

    def __init__(self, bench: SimulatedBench, time_scale: float = 1.0) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.bench = bench
        self.time_scale = time_scale
        self._lock = threading.Lock()
        self._t0 = time.monotonic()

    def now_s(self) -> float:
        """Lab time: wall time since the world was made, times ``time_scale`` (a scale of
        10 runs moves, settling and frame times 10x faster than real time)."""
        return (time.monotonic() - self._t0) * self.time_scale

    def host_monotonic_ns(self, lab_time_s: float) -> int:
        """The host's ``time.monotonic_ns`` at lab time ``lab_time_s`` (``now_s``'s
        inverse): how a frame's render time becomes its capture stamp."""
        return int(round((self._t0 + lab_time_s / self.time_scale) * 1e9))

    def capture(self, ahead_s: float = 0.0):
        """Render the scene as the turntable stands ``ahead_s`` (real seconds) from now:
        the middle of an acquisition that starts now (an emulated camera's command) is
        that far ahead; returns (time_s, frame, T_lab, T_true, encoders): the lab time
        rendered, the lab's reference (encoders + nominal geometry) and the exact pose
        rendered, both ``T_camera_target``."""
        with self._lock:  # the turntable state; rendering happens outside the lock
            t = self.now_s() + ahead_s * self.time_scale
            T_true, T_lab, enc = self.bench.poses_at(t)
            subframes = self.bench.subframe_poses(t, T_true)
            sensor = self.bench.sensor
        frame = render_frame(
            self.bench.camera,
            self.bench.scene,
            T_true,
            sensor,
            self.bench.rng,
            time_s=t,
            subframe_poses=subframes,
        )
        return t, frame, T_lab, T_true, enc

    def move_to(self, setpoints: dict[str, float]) -> None:
        with self._lock:
            self.bench.turntable.move_to(setpoints, self.now_s())

    def run_profile(self, axis: str, profile: MotionProfile) -> MotionProfile:
        """Start ``profile`` on ``axis`` now, from where it stands (Turntable.run_profile);
        returns it as started."""
        with self._lock:
            return self.bench.turntable.run_profile(axis, profile, self.now_s())

    def stop(self) -> None:
        with self._lock:
            self.bench.turntable.stop(self.now_s())

    def motion_status(self) -> MotionStatus:
        """Encoders read now, stamped with the lab time of the reading (the clock of the
        camera's frames), and the profile running, if any."""
        with self._lock:
            t = self.now_s()
            tt = self.bench.turntable
            running = tt.running_profile(t)
            profile = None
            if running is not None:
                axis, plan = running
                profile = ProfileStatus(axis, plan.profile.kind, t - plan.t0_s, plan.duration_s)
            return MotionStatus(
                positions=tt.encoder_position(t),
                targets=tt.target_position(),
                busy=tt.is_busy(t),
                settled=tt.is_settled(t),
                stopped=tt.is_stopped(),
                time_s=t,
                profile=profile,
            )

    def set_sensor(self, **changes) -> None:
        with self._lock:
            self.bench.sensor = replace(self.bench.sensor, **changes)


def make_sim_world(
    *,
    target_distance_mm: float = 15000.0,
    start_rail_mm: float = 13000.0,
    catalog: Catalog | None = None,
    seed: int = 0,
    time_scale: float = 1.0,
) -> SimWorld:
    """A lab with the target ``target_distance_mm`` from the turntable, camera on the rail
    at ``start_rail_mm`` (so the initial range is their difference)."""
    turntable = Turntable(seed=seed)
    # Put the rail at its start position long before t = 0, so it is settled at start.
    turntable.move_to({"rail": start_rail_mm}, time_s=-1.0e4)
    bench = SimulatedBench(
        scene=TargetScene(catalog or paper_target()),
        geometry=LabGeometry(
            target_distance_mm=target_distance_mm, mount_error=paper_mount_error()
        ),
        turntable=turntable,
        seed=seed,
    )
    return SimWorld(bench, time_scale)


class SimCamera:
    """The simulated ToF camera of a ``SimWorld`` (implements ``CameraDriver``)."""

    name = "sim"

    def __init__(self, world: SimWorld, settings: CameraSettings | None = None) -> None:
        self.world = world
        self.model = world.bench.camera
        self._settings = CameraSettings()
        self._pacer = FramePacer(self._settings.frame_rate_hz)
        self._index = 0
        self.apply_settings(settings or self._settings)

    def read(self, timeout_s: float) -> CameraFrame:
        """Renders the scene now. Its stamps: ``capture_ns`` the render's lab time on the
        host's clock (the frame then takes the render's duration to arrive, as a real
        frame takes its exposure and read-out), ``sequence`` the renders made (the
        simulated camera renders only the frames it delivers: it loses none)."""
        skipped = self._pacer.wait(timeout_s)
        t, frame, T_lab, T_true, enc = self.world.capture()
        self._index += 1
        return CameraFrame(
            gray=frame.gray,
            distance_mm=frame.distance_mm,
            time_s=t,
            index=self._index,
            T_camera_target_exact=T_true,
            T_camera_target_lab=T_lab,
            meta={"integration_time_us": frame.integration_time_us, "encoders": enc},
            capture_ns=self.world.host_monotonic_ns(t),
            sequence=self._index,
            slots_skipped=skipped,
        )

    @property
    def range_bias_sigma_mm(self) -> float | None:
        """The simulated sensor's ranges carry no common offset unless its systematic
        errors are switched on (None: the pipeline's default prior)."""
        return 0.0 if self.world.bench.sensor.systematic is None else None

    def get_settings(self) -> CameraSettings:
        return self._settings

    def limits(self) -> CameraLimits:
        """The simulated sensor's integration limits; any modulation frequency of 1-24 MHz."""
        return CameraLimits(integration_time_us=self.world.bench.sensor.integration_limits_us)

    def describe(self) -> dict[str, str]:
        return {"model": "tofpose simulated ToF camera", "firmware": __version__, "link": "up"}

    def apply_settings(self, settings: CameraSettings) -> CameraSettings:
        lo, hi = self.world.bench.sensor.integration_limits_us
        applied = replace(
            settings, integration_time_us=float(np.clip(settings.integration_time_us, lo, hi))
        )
        self.world.set_sensor(
            modulation_frequency_hz=applied.modulation_frequency_mhz * 1e6,
            integration_time_us=applied.integration_time_us,
            auto_exposure=applied.auto_exposure,
        )
        self._pacer.set_rate(applied.frame_rate_hz)
        self._settings = applied
        # the model the live pipeline measures with: its distances now wrap at c / (2 f)
        # (a new model only for a new frequency: the live loop rebuilds its pipeline then)
        hz = applied.modulation_frequency_mhz * 1e6
        if hz != self.model.modulation_frequency_hz:
            self.model = replace(self.model, modulation_frequency_hz=hz)
        return applied

    def close(self) -> None:
        self._pacer.close()


class SimMotion:
    """The simulated turntable + rail of a ``SimWorld`` (implements ``MotionDriver``)."""

    name = "sim"
    profile_unavailable = None  # runs motion profiles on its rotary axes

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self.axes = {
            n: AxisLimits(n, s.unit, s.min_pos, s.max_pos, s.max_rate, s.max_accel)
            for n, s in world.bench.turntable.axes.items()
        }

    def move_to(self, setpoints: dict[str, float]) -> None:
        self.world.move_to(setpoints)

    def run_profile(self, axis: str, profile: MotionProfile) -> None:
        self.world.run_profile(axis, profile)

    def stop(self) -> None:
        self.world.stop()

    def status(self) -> MotionStatus:
        return self.world.motion_status()

    def describe(self) -> dict[str, str]:
        return {
            "model": "tofpose simulated turntable + rail",
            "firmware": __version__,
            "link": "up",
        }

    def close(self) -> None:
        pass
