"""Replay of an HDF5 recording (docs/architecture.md §7) as a camera, looping, at the recorded rate
or a chosen one."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from backend.drivers.base import CameraError, CameraFrame, CameraLimits, CameraSettings
from backend.drivers.pacing import FramePacer
from tofpose.core.geometry import RigidTransform
from tofpose.io.recording import RecordingError, open_recording

DEFAULT_RATE_HZ = 10.0


def recorded_rate_hz(time_s: np.ndarray) -> float:
    """Median frame rate of a recording's time stamps (``DEFAULT_RATE_HZ`` if unknown)."""
    dt = np.diff(np.asarray(time_s, float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    return float(1.0 / np.median(dt)) if dt.size else DEFAULT_RATE_HZ


def _pose_at(
    R_all: np.ndarray | None, t_all_mm: np.ndarray | None, i: int
) -> RigidTransform | None:
    """Frame ``i`` of a recording's pose datasets (R (N, 3, 3), t (N, 3) mm), or None when
    the recording has none."""
    if R_all is None or t_all_mm is None:
        return None
    return RigidTransform(R_all[i], t_all_mm[i])


class PlaybackClock:
    """A recording's own stamps (``time_s``, s) mapped to the host's monotonic clock
    during playback: ``capture_ns(recorded_s, released_ns, period_s)``.

    The first frame, the first of every loop (``restart``) and any frame released more
    than one period away from where the mapping puts it (a pipeline slower than the
    recording, or a gap in the recorded stamps, which the pacer plays at its steady
    rate) anchor the mapping at their release; from an anchor on, a frame's capture is
    the anchor's release plus its recorded time since the anchor's, scaled by
    ``speed`` (the playback rate over the recorded one), and never later than its own
    release.
    """

    def __init__(self, speed: float = 1.0) -> None:
        self.speed = speed
        self._anchor: tuple[float, int] | None = None  # (recorded s, host ns)

    def restart(self) -> None:
        self._anchor = None

    def capture_ns(self, recorded_s: float, released_ns: int, period_s: float) -> int:
        if self._anchor is not None:
            rec0, host0 = self._anchor
            mapped = host0 + int(round((recorded_s - rec0) / self.speed * 1e9))
            if abs(released_ns - mapped) <= period_s * 1e9:
                return min(mapped, released_ns)  # never after the frame was released
        self._anchor = (recorded_s, released_ns)
        return released_ns


class ReplayCamera:
    """Plays a recording's frames in a loop (implements ``CameraDriver``).

    Frame times are stream times (seconds since the replay started), so they increase
    across loops; ``meta`` carries the recording index, its own time stamp and the loop
    count, and ``meta["discontinuity"]`` is True on the first frame of every loop. The
    recording's ``/truth`` is each frame's exact pose and its ``/reference`` (older
    files: ``/lab_truth``) the lab's reference (``T_camera_target_exact`` /
    ``T_camera_target_lab``, None when absent).
    A frame's ``capture_ns`` is its recorded stamp mapped to playback (``PlaybackClock``);
    its ``sequence`` the frames played (a replay loses none).
    Raises ``RecordingError`` at construction if the file is not a valid recording.
    """

    name = "replay"

    def __init__(self, path: str | Path, rate_hz: float | None = None) -> None:
        self.path = Path(path)
        self._rec = open_recording(self.path)
        if self._rec.n_frames == 0:
            self._rec.close()
            raise RecordingError(f"{self.path}: the recording holds no frames")
        self.model = self._rec.camera
        self.catalog = self._rec.catalog
        self.recorded_rate_hz = recorded_rate_hz(self._rec.time_s)
        rate = rate_hz or self.recorded_rate_hz
        self._settings = CameraSettings(frame_rate_hz=rate, auto_exposure=False)
        self._pacer = FramePacer(rate)
        self._clock = PlaybackClock(rate / self.recorded_rate_hz)
        self._count = 0
        self._t0: float | None = None

    def read(self, timeout_s: float) -> CameraFrame:
        skipped = self._pacer.wait(timeout_s)
        released_ns = time.monotonic_ns()
        if self._t0 is None:
            self._t0 = time.monotonic()
        n = self._rec.n_frames
        i = self._count % n
        try:
            gray, dist, rec_t = self._rec.frame(i)
        except RecordingError as exc:
            raise CameraError(str(exc)) from exc
        if i == 0:
            self._clock.restart()
        capture_ns = self._clock.capture_ns(rec_t, released_ns, 1.0 / self._pacer.rate_hz)
        self._count += 1
        return CameraFrame(
            gray=gray,
            distance_mm=dist,
            time_s=time.monotonic() - self._t0,
            index=self._count,
            T_camera_target_exact=_pose_at(self._rec.truth_R, self._rec.truth_t_mm, i),
            T_camera_target_lab=_pose_at(self._rec.lab_truth_R, self._rec.lab_truth_t_mm, i),
            meta={
                "recording_index": i,
                "recorded_time_s": rec_t,
                "loop": (self._count - 1) // n,
                "discontinuity": i == 0,
            },
            capture_ns=capture_ns,
            sequence=self._count,
            slots_skipped=skipped,
        )

    def get_settings(self) -> CameraSettings:
        return self._settings

    def describe(self) -> dict[str, str]:
        return {
            "model": f"replay of {self._rec.camera.name}",
            "address": str(self.path),
            "link": "up",
        }

    def limits(self) -> CameraLimits:
        """A recording's exposure and modulation are what they were: not settable."""
        return CameraLimits(integration_time_us=(0.0, 0.0), settable=False)

    def apply_settings(self, settings: CameraSettings) -> CameraSettings:
        """Only the frame rate can change; the rest is fixed by the recording."""
        self._settings = replace(self._settings, frame_rate_hz=settings.frame_rate_hz)
        self._pacer.set_rate(settings.frame_rate_hz)
        self._clock = PlaybackClock(settings.frame_rate_hz / self.recorded_rate_hz)
        return self._settings

    def close(self) -> None:
        self._pacer.close()
        self._rec.close()
