"""The two device interfaces the backend talks to (docs/architecture.md §8).

A camera yields (gray, distance, time) frame pairs and accepts settings; a motion system
moves axes to set-points, reports encoder positions and busy/settled state, and stops at
once. Simulated, replay and (later) real devices implement these Protocols. A motion
system may also run motion profiles (``run_profile``, tofpose.lab.motion_profile).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import RigidTransform
from tofpose.lab.motion_profile import LimitProblem, MotionProfile


class CameraError(RuntimeError):
    """The camera could not deliver a frame (disconnected, timed out, bad data)."""


class MotionError(RuntimeError):
    """The motion controller refused or failed a command."""


@dataclass(frozen=True)
class CameraSettings:
    """Acquisition settings common to ToF cameras.

    integration_time_us : exposure; ignored while ``auto_exposure`` is on.
    modulation_frequency_mhz : CW modulation; unambiguous range is c / (2 f).
    frame_rate_hz : frames per second delivered by ``read``.
    """

    integration_time_us: float = 500.0
    modulation_frequency_mhz: float = 6.0
    frame_rate_hz: float = 10.0
    auto_exposure: bool = True


@dataclass(frozen=True)
class CameraLimits:
    """What a camera's settings may be set to (a campaign's camera settings are checked
    against them before it is stored).

    integration_time_us : (min, max) exposure, us.
    modulation_frequencies_mhz : the modulation frequencies the camera supports, MHz;
        None when any frequency in ``modulation_range_mhz`` is accepted.
    modulation_range_mhz : (min, max) MHz, for a camera without a fixed list.
    settable : False for a source whose settings cannot change (a replayed recording).
    """

    integration_time_us: tuple[float, float]
    modulation_frequencies_mhz: tuple[float, ...] | None = None
    modulation_range_mhz: tuple[float, float] = (1.0, 24.0)
    settable: bool = True


@dataclass
class CameraFrame:
    """One frame pair.

    gray : (H, W) uint16 counts; distance_mm : (H, W) float32 radial distance, NaN invalid.
    time_s : the instant the frame's pose is of, the middle of its acquisition where the
        driver knows it (the simulator: exactly; the TOFcam-660: from the acquisition
        command and the integration time), in seconds (monotonic within a stream).
    index : running frame number of this driver.
    T_camera_target_exact : the pose that produced the frame (docs/architecture.md §3,
        "Truth"), known only to a simulator (what it rendered) or a recording's ``/truth``;
        else None. Reports call it the ``exact`` reference.
    T_camera_target_lab : the lab's reference for the frame: the encoders through the
        nominal camera mount and target placement (the simulator, or a real bench through
        ``EncoderReferencedCamera``), or a recording's ``/reference``; else None. It
        differs from the exact pose by the bench's own mount and placement errors.
    meta : driver-specific extras (integration time, encoder readings, recording index).
    capture_ns : when the device captured the frame, on the host's monotonic clock
        (``time.monotonic_ns``): the device's own clock mapped to the host's (the
        simulator's render time, the TOFcam-660's acquisition command, a replay's
        recorded stamp mapped to playback; docs/server.md, "Latency and dropped
        frames"); None when the driver cannot say.
    sequence : the device's own frame counter, unwrapped (never decreasing within a
        stream), whose gaps are frames the camera lost; None when it has none.
    slots_skipped : frames the camera's rate offered since the previous ``read`` that
        the reader was too busy to take (``FramePacer.wait``): the pipeline's drops.
    """

    gray: np.ndarray
    distance_mm: np.ndarray
    time_s: float
    index: int
    T_camera_target_exact: RigidTransform | None = None
    T_camera_target_lab: RigidTransform | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    capture_ns: int | None = None
    sequence: int | None = None
    slots_skipped: int = 0


@runtime_checkable
class CameraDriver(Protocol):
    """A ToF camera. ``read`` blocks for at most ``timeout_s`` and raises ``CameraError``
    (or ``TimeoutError``) when no frame arrives; it is called from one thread only."""

    name: str
    model: CameraModel

    def read(self, timeout_s: float) -> CameraFrame: ...

    def get_settings(self) -> CameraSettings: ...

    def apply_settings(self, settings: CameraSettings) -> CameraSettings:
        """Apply and return what the device actually uses (it may clamp)."""
        ...

    # Optional: ``limits() -> CameraLimits`` (what the settings may be set to).

    def close(self) -> None: ...


@dataclass(frozen=True)
class AxisLimits:
    """Soft limits of one axis; rotary axes in degrees, the rail in mm. ``max_rate`` per
    second, ``max_accel`` per second^2 (None: the motion system does not say, and runs no
    profiles on that axis)."""

    name: str
    unit: str
    min_pos: float
    max_pos: float
    max_rate: float
    max_accel: float | None = None

    def check(self, value: float) -> str | None:
        """Why ``value`` is not an acceptable set-point, or None."""
        if not np.isfinite(value):
            return f"{self.name} set-point must be a finite number"
        if not self.min_pos <= value <= self.max_pos:
            return (
                f"{self.name} set-point {value:.15g} {self.unit} is outside the soft limits "
                f"[{self.min_pos:.15g}, {self.max_pos:.15g}] {self.unit}"
            )
        return None


def soft_limit_problems(axes: dict[str, AxisLimits], setpoint: dict[str, float]) -> list[str]:
    """Every reason ``setpoint`` ({axis: value}) cannot be sent to a motion system with
    ``axes``: unknown axes and values outside the soft limits (empty when acceptable)."""
    problems = []
    for name, value in setpoint.items():
        axis = axes.get(name)
        if axis is None:
            problems.append(f"this motion system has no {name} axis (axes: {sorted(axes)})")
        elif (why := axis.check(value)) is not None:
            problems.append(why)
    return problems


def profile_axis_problem(axes: dict[str, AxisLimits], axis: str) -> LimitProblem | None:
    """Why no profile can run on ``axis`` of a motion system with ``axes`` (unknown,
    linear, or without an acceleration limit to check against), or None."""
    limits = axes.get(axis)
    if limits is None:
        why = f"this motion system has no {axis} axis (axes: {sorted(axes)})"
    elif limits.unit != "deg":
        why = f"profiles run on rotary axes; {axis} is in {limits.unit}"
    elif limits.max_accel is None:
        why = f"the motion system reports no acceleration limit for {axis} to check against"
    else:
        return None
    return LimitProblem("axis", why)


def profile_problems(
    axes: dict[str, AxisLimits], axis: str, profile: MotionProfile
) -> list[LimitProblem]:
    """Every reason ``profile`` (run from its ``start_deg``) cannot run on ``axis`` of a
    motion system with ``axes``: the axis itself (``profile_axis_problem``), its soft
    limits, its rate and acceleration limits (empty when it can run)."""
    if (problem := profile_axis_problem(axes, axis)) is not None:
        return [problem]
    lim = axes[axis]
    assert lim.max_accel is not None  # profile_axis_problem refuses an axis without one
    return profile.limit_problems(axis, lim.min_pos, lim.max_pos, lim.max_rate, lim.max_accel)


@dataclass(frozen=True)
class ProfileStatus:
    """A motion profile running on one axis: what it is, and how far it has come (s)."""

    axis: str
    kind: str
    elapsed_s: float
    duration_s: float

    @property
    def remaining_s(self) -> float:
        return max(self.duration_s - self.elapsed_s, 0.0)


@dataclass(frozen=True)
class MotionStatus:
    """Encoder read-back and state; positions keyed by axis name (deg / mm).

    time_s : when the encoders were read, on the clock of the cameras' ``time_s`` where
        the driver knows one (the simulated lab's clock; else the host's monotonic
        clock), None if the driver cannot say.
    profile : the motion profile running now, else None.
    """

    positions: dict[str, float]
    targets: dict[str, float]
    busy: bool
    settled: bool
    stopped: bool = False
    time_s: float | None = None
    profile: ProfileStatus | None = None


@runtime_checkable
class MotionDriver(Protocol):
    """A turntable (+ rail). Set-points are validated by the caller against ``axes``
    before ``move_to``; ``stop`` must work at any time.

    Optional: ``run_profile(axis, profile)`` starts a motion profile from the axis'
    position now (checked by the caller with ``profile_problems``; ends on its own or at
    ``stop``), and ``profile_unavailable`` (None, or why this system cannot run one).
    """

    name: str
    axes: dict[str, AxisLimits]

    def move_to(self, setpoints: dict[str, float]) -> None: ...

    def stop(self) -> None: ...

    def status(self) -> MotionStatus: ...

    def close(self) -> None: ...


@runtime_checkable
class ProfileMotionDriver(MotionDriver, Protocol):
    """A motion system that runs motion profiles (``MotionDriver``'s optional part)."""

    def run_profile(self, axis: str, profile: MotionProfile) -> None: ...
