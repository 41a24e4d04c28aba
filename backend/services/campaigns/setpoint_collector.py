"""Measuring one set-point: move, settle, collect (docs/campaigns.md, "What counts as a
measurement" and "Dynamic campaigns").

``SetPointCollector`` takes the motion service, a frame source and a policy and returns
the frames it kept (``SetPointRecord``); it stores nothing and schedules nothing, so the
campaign runner and a test with the simulated devices drive it the same way. A static
set-point runs entirely in the caller's thread; a dynamic one reads the encoders in the
background thread of ``EncoderTrace``.

Static set-point: move; wait until the motion system reports settled; then count only
frames captured after that moment and at least ``settle_s`` of device time later, whose
encoder read-back (when the driver gives it) is at the set-point; collect ``frames`` of
them. Anything that keeps the set-point from completing (a device fault, a lost pose
lock, the caller's pause, cancel or shutdown) raises ``SetPointHalt`` with the state the
campaign goes to and the reason.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import NamedTuple, Protocol

from backend.services.campaigns.campaign_states import CampaignState
from backend.services.campaigns.encoder_trace import EncoderTrace, EncoderTraceError
from backend.services.live.acquisition import DeviceHealth, LiveSample
from backend.services.live.hub import Subscription
from backend.services.motion import MotionDeviceError, MotionService
from tofpose.sim.bench import LabGeometry

log = logging.getLogger(__name__)

# Encoder read-back farther than this from the set-point means the axis is not there.
AT_SETPOINT_TOLERANCE = {"yaw": 0.05, "pitch": 0.05, "roll": 0.05, "rail": 1.0}
# A profile pauses when the motion status has not been read for this long (s, wall time).
STALE_TRACE_S = 1.0
# Frames in a row that may report another integration time than the one set before the
# set-point pauses (the settings are applied before the move, so none should).
MAX_OTHER_EXPOSURE_FRAMES = 20
# Frames whose encoders are still off the set-point that may arrive after the settle
# before the first one at it: a frame captured while the table moved can reach the runner
# after the motion service reports settled (its render or measurement ran late on a
# loaded machine); beyond these the table did not reach the set-point, and it pauses.
MAX_UNSETTLED_FRAMES = 10
# A frame's reported integration time matches the one set within this (the TOFcam-660
# reports whole microseconds).
EXPOSURE_MATCH_US = 0.5


class SetPointHalt(Exception):  # noqa: N818 (control flow, not an error)
    """The set-point cannot complete: the campaign goes to ``status`` with ``reason``."""

    def __init__(self, status: CampaignState, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


def _paused(reason: str) -> SetPointHalt:
    return SetPointHalt(CampaignState.PAUSED, reason)


class FrameSource(Protocol):
    """Processed frames in the order they were captured."""

    health: DeviceHealth
    """The camera's state, named when no frame comes."""

    def get(self, timeout_s: float) -> LiveSample | None:
        """The next frame, waiting up to ``timeout_s``; None when none came."""
        ...

    def drain(self) -> None:
        """Forget the frames waiting to be read."""
        ...


class HubFrames:
    """The acquisition loop's frames through a hub subscription (the campaign runner's
    frame source)."""

    def __init__(self, sub: Subscription, health: DeviceHealth) -> None:
        self.sub = sub
        self.health = health

    def get(self, timeout_s: float) -> LiveSample | None:
        return self.sub.get(timeout_s)

    def drain(self) -> None:
        while self.sub.get(0.0) is not None:
            pass


@dataclass(frozen=True)
class CollectPolicy:
    """How a static set-point is measured: ``frames`` frames, counted from ``settle_s``
    (device time) after the first frame at rest; a pose lost for ``lock_timeout_s``
    pauses the campaign; ``integration_time_us``: the exposure set for the set-point
    (frames that report another do not count), None for any."""

    frames: int
    settle_s: float
    lock_timeout_s: float
    integration_time_us: float | None = None


@dataclass(frozen=True)
class CollectTiming:
    """How long to wait: between polls (``poll_s``), for a move to settle or a profile
    to end beyond its duration (``move_timeout_s``), for a frame (``frame_timeout_s``)."""

    poll_s: float = 0.05
    move_timeout_s: float = 600.0
    frame_timeout_s: float = 10.0


class CollectedFrame(NamedTuple):
    sample: LiveSample
    in_motion: bool | None
    """Taken while the set-point's profile ran; None at a static set-point."""


@dataclass(frozen=True)
class SetPointRecord:
    """The frames one set-point kept, in capture order."""

    index: int
    axes: dict[str, float]
    frames: list[CollectedFrame]


def _no_check(index: int) -> None:
    return None


def _no_frame_hook(sample: LiveSample, n_collected: int) -> None:
    return None


class SetPointCollector:
    """Move, settle, collect, for one set-point at a time.

    owner : the campaign the moves are made for (it must own the motion service), or
        None for moves a person could make.
    check : called with the set-point index between steps; raises ``SetPointHalt`` to
        leave the set-point (the runner's pause, cancel and shutdown).
    on_frame : called with each frame kept and how many are kept so far (the runner
        writes it to the raw recording and shows the progress).
    lab_geometry : the nominal lab geometry that turns a dynamic set-point's encoders
        into its lab reference.
    """

    def __init__(
        self,
        motion: MotionService,
        frames: FrameSource,
        *,
        timing: CollectTiming | None = None,
        owner: int | None = None,
        check: Callable[[int], None] = _no_check,
        on_frame: Callable[[LiveSample, int], None] = _no_frame_hook,
        lab_geometry: LabGeometry | None = None,
    ) -> None:
        self.motion = motion
        self.frames = frames
        self.timing = timing or CollectTiming()
        self.owner = owner
        self.check = check
        self.on_frame = on_frame
        self.lab_geometry = lab_geometry

    # -- static set-points ------------------------------------------------------------------
    def collect(self, index: int, axes: dict[str, float], policy: CollectPolicy) -> SetPointRecord:
        """Move to ``axes`` and collect ``policy.frames`` frames taken at rest."""
        self.move_and_settle(index, axes)
        at_rest = self._at_rest(index, policy.settle_s, policy.integration_time_us, axes)
        last_ok_s = None
        out: list[CollectedFrame] = []
        while len(out) < policy.frames:
            sample, t, t_ready = next(at_rest)
            last_ok_s = t_ready if last_ok_s is None else last_ok_s
            _check_at_setpoint(index, axes, sample)
            if sample.result.ok:
                last_ok_s = t
            elif t - last_ok_s > policy.lock_timeout_s:
                raise _paused(
                    f"pose lock lost for {t - last_ok_s:.1f} s at set-point {index}: "
                    f"{sample.result.reason}"
                )
            out.append(CollectedFrame(sample, None))
            self.on_frame(sample, len(out))
        return SetPointRecord(index, dict(axes), out)

    def move_and_settle(self, index: int, axes: dict[str, float]) -> None:
        """Move to ``axes`` (if any) and wait until the motion system reports settled."""
        self.check(index)
        if not axes:
            return
        try:
            self.motion.move(axes, by=self.owner)
        except Exception as exc:
            if isinstance(exc, MotionDeviceError):
                # a controller that takes a set-point axis by axis may have started some
                # axes before it failed on another: stop the table before letting it go
                self._stop_table(index)
            raise _paused(f"move to set-point {index} failed: {exc}") from exc
        try:
            self._settle(index)
        except BaseException:
            # a pause, cancel, shutdown or failure while the table travels stops it: the
            # campaign gives the motion system back, and nobody else may move a table
            # that is still on its way (a profile's slew is stopped the same way)
            self._stop_table(index)
            raise

    def _settle(self, index: int) -> None:
        """Wait until the motion system reports settled after a move."""
        deadline = time.monotonic() + self.timing.move_timeout_s
        while True:
            self.check(index)
            try:
                st = self.motion.status()
            except Exception as exc:
                raise _paused(f"motion status failed at set-point {index}: {exc}") from exc
            if st.stopped:
                raise self._stopped(index)
            if st.settled and not st.busy:
                return
            if time.monotonic() > deadline:
                raise _paused(
                    f"set-point {index} not settled within {self.timing.move_timeout_s:g} s"
                )
            time.sleep(self.timing.poll_s)

    def _at_rest(
        self,
        index: int,
        settle_s: float,
        integration_time_us: float | None = None,
        axes: dict[str, float] | None = None,
    ) -> Iterator[tuple[LiveSample, float, float]]:
        """(sample, its device time, the device time from which frames count) of every
        frame captured after now (the motion system has settled) that the pipeline
        measured, from ``settle_s`` after the first of them at the set-point ``axes``
        (up to ``MAX_UNSETTLED_FRAMES`` frames off it are still in flight from the move);
        with ``integration_time_us`` only frames that report it (or none)."""
        settled_unix_s = time.time()
        self.frames.drain()  # frames queued before the settle do not count
        t_ready = None
        other_exposure = unsettled = 0
        while True:
            sample = self._next_sample(index)
            if sample.captured_unix_s < settled_unix_s or not sample.measured:
                continue  # before the settle, or while the pipeline's kernels compile
            if t_ready is None and axes is not None and _off_setpoint(axes, sample):
                unsettled += 1
                if unsettled > MAX_UNSETTLED_FRAMES:
                    _check_at_setpoint(index, axes, sample)
                continue  # captured while the table still moved, arrived late
            if not _exposed_as_set(sample, integration_time_us):
                other_exposure += 1
                if other_exposure > MAX_OTHER_EXPOSURE_FRAMES:
                    raise _paused(
                        f"the camera's frames at set-point {index} report an integration "
                        f"time of {sample.frame.meta.get('integration_time_us')} us, not the "
                        f"{integration_time_us:g} us set for it"
                    )
                continue
            other_exposure = 0
            t = float(sample.frame.time_s)
            t_ready = t + settle_s if t_ready is None else t_ready
            if t >= t_ready:
                yield sample, t, t_ready

    def _next_sample(self, index: int) -> LiveSample:
        """The next frame; pauses the campaign after ``frame_timeout_s`` without one."""
        waited_since = time.monotonic()
        while True:
            self.check(index)
            sample = self.frames.get(self.timing.poll_s)
            if sample is not None:
                return sample
            if time.monotonic() - waited_since > self.timing.frame_timeout_s:
                h = self.frames.health
                raise _paused(
                    f"no frame for {self.timing.frame_timeout_s:g} s at set-point "
                    f"{index} (camera {h.state}: {h.last_error})"
                )

    # -- dynamic set-points -----------------------------------------------------------------
    def collect_profile(
        self,
        index: int,
        axes: dict[str, float],
        spec: dict,
        settle_s: float,
        integration_time_us: float | None = None,
    ) -> SetPointRecord:
        """A dynamic set-point (docs/campaigns.md, "Dynamic campaigns"): move and settle;
        rest ``rest_s``; run the profile from the axis' encoder position; rest ``rest_s``
        after it has ended. Every measured frame of the three phases is kept, its encoders
        and lab reference interpolated to its capture time (``EncoderTrace``), with
        whether the profile ran at that time. A lost pose does not pause it: frames lost
        in motion are what the report counts."""
        axis, rest_s = spec["axis"], float(spec.get("rest_s", 2.0))
        self.move_and_settle(index, axes)
        trace = self._start_trace(index)
        running = False
        try:
            out: list[CollectedFrame] = []
            ran: tuple[float, float, float] | None = None  # (t0, t_end, deadline) once started
            for sample, t, t_ready in self._at_rest(index, settle_s, integration_time_us, axes):
                if ran is None and t >= t_ready + rest_s:
                    running = True  # from here on, any way out stops the table first
                    t0, t_end = self._start_profile(index, axis, spec)
                    ran = t0, t_end, time.monotonic() + (t_end - t0) + self.timing.move_timeout_s
                in_motion = ran is not None and ran[0] <= t <= ran[1]
                out.append(CollectedFrame(self._referenced(sample, trace), in_motion))
                self.on_frame(out[-1].sample, len(out))
                if ran is not None and self._profile_over(
                    index, axis, trace, t, ran[1] + rest_s, ran[2]
                ):
                    running = False
                    return SetPointRecord(index, dict(axes), out)
            raise _paused(f"the frames ended at set-point {index}")  # an endless source
        except BaseException:
            if running:  # a pause, cancel, shutdown or failure stops the slew it interrupts
                self._stop_table(index)
            raise
        finally:
            trace.stop()

    def _start_trace(self, index: int) -> EncoderTrace:
        trace = EncoderTrace(self.motion.require())
        try:
            trace.start()
        except EncoderTraceError as exc:
            raise SetPointHalt(CampaignState.FAILED, str(exc)) from exc
        except Exception as exc:
            raise _paused(f"motion status failed at set-point {index}: {exc}") from exc
        return trace

    def _profile_over(
        self,
        index: int,
        axis: str,
        trace: EncoderTrace,
        t: float,
        t_done: float,
        deadline: float,
    ) -> bool:
        """Whether the profile has ended and the table rests again at device time ``t``
        (from ``t_done`` on); pauses when the encoders go unread, the table is stopped or
        the profile runs past ``deadline`` (monotonic)."""
        if trace.stale_s() > STALE_TRACE_S:
            why = trace.error or "no answer"
            raise _paused(
                f"the motion status was not read for {trace.stale_s():.1f} s during "
                f"the profile of set-point {index}: {why}"
            )
        st = trace.latest
        if st.stopped:
            raise self._stopped(index)
        if t < t_done:
            return False
        if st.profile is None and st.settled and not st.busy:
            return True
        if time.monotonic() > deadline:
            raise _paused(
                f"the {axis} profile of set-point {index} did not end within "
                f"{self.timing.move_timeout_s:g} s of its duration"
            )
        return False

    def _start_profile(self, index: int, axis: str, spec: dict) -> tuple[float, float]:
        """Start the set-point's profile from the axis' encoder position now; returns
        (start, end) on the encoders' clock."""
        motion = self.motion
        if (why := motion.profile_unavailable) is not None:
            raise SetPointHalt(
                CampaignState.FAILED,
                f"set-point {index}: the "
                f"{motion.require().name!r} motion system cannot run motion "
                f"profiles ({why})",
            )
        try:
            start_deg = motion.status().positions[axis]
            profile = motion.profile_of(axis, spec).started_at(start_deg)
        except Exception as exc:
            raise _paused(f"set-point {index}: cannot prepare the profile: {exc}") from exc
        problems = motion.profile_problems(axis, profile)
        if problems:
            raise SetPointHalt(
                CampaignState.FAILED,
                f"set-point {index}: " + "; ".join(p.message for p in problems),
            )
        try:
            motion.run_profile(axis, profile, by=self.owner)
            st = motion.status()
        except Exception as exc:
            raise _paused(f"set-point {index}: the profile failed: {exc}") from exc
        if st.time_s is None:
            raise _paused(
                f"set-point {index}: the motion system does not say when it read its encoders"
            )
        elapsed = st.profile.elapsed_s if st.profile is not None else 0.0
        t0 = float(st.time_s) - elapsed
        return t0, t0 + profile.duration_s

    def _stopped(self, index: int) -> SetPointHalt:
        """The pause for a table found stopped at set-point ``index``: a person's STOP
        (latched in the motion service) reads "STOP pressed", as the campaign service's
        own request does, whichever of the two the runner sees first."""
        if self.motion.stop_latched:
            return _paused(f"STOP pressed at set-point {index}")
        return _paused(f"the turntable was stopped at set-point {index}")

    def _stop_table(self, index: int) -> None:
        """Stop the table after a move or a profile was interrupted; a stop that fails is
        logged (the campaign is leaving anyway, and its reason says why)."""
        try:
            self.motion.stop(by=self.owner)
        except Exception:
            log.exception("stopping the table at set-point %d failed", index)

    def _referenced(self, sample: LiveSample, trace: EncoderTrace) -> LiveSample:
        """The sample with the encoders interpolated to its capture time and the lab
        reference from them (the nominal geometry), when the trace covers that time."""
        enc = trace.at(float(sample.frame.time_s))
        f = sample.frame
        if enc is None:  # no reading around its capture: no reference rather than a late one
            meta = {k: v for k, v in f.meta.items() if k != "encoders"}
            return replace(sample, frame=replace(f, T_camera_target_lab=None, meta=meta), cache={})
        T_lab = f.T_camera_target_lab
        if self.lab_geometry is not None:
            T_lab = self.lab_geometry.T_camera_target(enc, true=False)
        frame = replace(f, T_camera_target_lab=T_lab, meta={**f.meta, "encoders": enc})
        return replace(sample, frame=frame, cache={})


def _exposed_as_set(sample: LiveSample, integration_time_us: float | None) -> bool:
    """Whether the frame was taken with ``integration_time_us`` (True when none is set or
    the camera reports none)."""
    reported = sample.frame.meta.get("integration_time_us")
    if integration_time_us is None or reported is None:
        return True
    return abs(float(reported) - integration_time_us) <= EXPOSURE_MATCH_US


def _off_setpoint(axes: dict[str, float], sample: LiveSample) -> list[str]:
    """The axes whose encoder read-back in the frame (if any) is off the set-point
    ``axes`` by more than ``AT_SETPOINT_TOLERANCE``."""
    enc = sample.frame.meta.get("encoders") or {}
    return [
        a
        for a, v in axes.items()
        if a in enc and abs(enc[a] - v) > AT_SETPOINT_TOLERANCE.get(a, 0.05)
    ]


def _check_at_setpoint(index: int, axes: dict[str, float], sample: LiveSample) -> None:
    """Pauses when the frame's encoder read-back (if any) is off the set-point."""
    if off := _off_setpoint(axes, sample):
        raise _paused(f"the turntable left set-point {index} (axes {off})")
