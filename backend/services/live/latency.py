"""Per-frame time stamps, frame accounting and the live latency statistics.

Every stamp is an integer of nanoseconds on the host's monotonic clock
(``time.monotonic_ns``), so that differences are latencies whatever the wall clock does
(NTP steps, daylight saving); ``ClockAnchor`` pairs one monotonic reading with the wall
clock read at the same moment, which turns any stamp into UTC.

A frame's stamps (``FrameStamps``):

- capture: when the device took the frame, on its own clock mapped to the host's
  (the driver's ``CameraFrame.capture_ns``: the simulator's render time, the
  TOFcam-660's acquisition command, a replay's recorded stamp mapped to playback;
  docs/server.md, "Latency and dropped frames"); the arrival when the driver cannot say;
- arrival: when the driver handed the frame to the acquisition loop;
- pose ready: when the pipeline and the relative-state filter were done with it;
- sent: when a WebSocket client's message for it was handed to that client's socket
  (one per client, so not part of the frame's record).

Frames are counted where they are lost (``DropCounts``): by the camera (gaps in its own
frame counter, ``CameraFrame.sequence``, where it has one), by the pipeline (frames the
camera's rate offered while the loop was busy, ``CameraFrame.slots_skipped``) and by the
clients (the hub's per-subscriber ``dropped``).

``LiveStatistics`` keeps the frames of a sliding window (the last ``window_s`` seconds,
at most ``max_frames``) and the totals since the server started; its ``snapshot`` gives
the median and 95th percentile of each latency over the window.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

NS_PER_MS = 1_000_000
DEFAULT_WINDOW_S = 10.0
DEFAULT_MAX_FRAMES = 1000


@dataclass(frozen=True)
class ClockAnchor:
    """One moment read on both clocks: ``monotonic_ns`` (``time.monotonic_ns``) and
    ``wall_ns`` (``time.time_ns``, UTC ns since the Unix epoch)."""

    monotonic_ns: int
    wall_ns: int

    @classmethod
    def now(cls) -> ClockAnchor:
        return cls(time.monotonic_ns(), time.time_ns())

    def wall_ns_of(self, monotonic_ns: int) -> int:
        """The UTC ns of a monotonic stamp."""
        return self.wall_ns + (monotonic_ns - self.monotonic_ns)


@dataclass(frozen=True)
class FrameStamps:
    """The host-monotonic ns stamps of one frame (module docstring).

    capture_from_device : False when the driver gave no capture time and ``capture_ns``
        is the arrival.
    """

    capture_ns: int
    arrival_ns: int
    pose_ready_ns: int
    capture_from_device: bool = True

    @property
    def capture_to_arrival_ms(self) -> float:
        return (self.arrival_ns - self.capture_ns) / NS_PER_MS

    @property
    def capture_to_pose_ms(self) -> float:
        return (self.pose_ready_ns - self.capture_ns) / NS_PER_MS

    def capture_to_sent_ms(self, sent_ns: int) -> float:
        return (sent_ns - self.capture_ns) / NS_PER_MS


class SequenceGaps:
    """Frames a camera lost, from its own frame counter: ``observe`` returns how many
    numbers were skipped since the previous frame (0 for the first frame, and after a
    counter that went backwards: the device restarted)."""

    def __init__(self) -> None:
        self._last: int | None = None

    def observe(self, sequence: int | None) -> int:
        if sequence is None:
            return 0
        last, self._last = self._last, sequence
        if last is None or sequence <= last:
            return 0
        return sequence - last - 1


@dataclass(frozen=True)
class LatencySummary:
    """Median and 95th percentile (linear interpolation, numpy's default) of ``n``
    latencies in ms; both None when ``n`` is 0."""

    median_ms: float | None
    p95_ms: float | None
    n: int

    @classmethod
    def of(cls, values_ms: np.ndarray) -> LatencySummary:
        """values_ms : ndarray of shape (n,)."""
        v = np.asarray(values_ms, float)
        if v.size == 0:
            return cls(None, None, 0)
        median, p95 = np.percentile(v, [50.0, 95.0])
        return cls(float(median), float(p95), int(v.size))


@dataclass(frozen=True)
class DropCounts:
    """Frames lost, by where. ``camera`` is None for a camera without a frame counter
    (its losses cannot be seen)."""

    camera: int | None
    pipeline: int
    clients: int


@dataclass(frozen=True)
class LatencySnapshot:
    """The statistics at one moment (``LiveStatistics.snapshot``)."""

    window_s: float
    frames_in_window: int
    capture_to_arrival: LatencySummary
    capture_to_pose: LatencySummary
    capture_to_sent: LatencySummary
    dropped_in_window: DropCounts
    dropped_total: DropCounts
    frames_total: int
    anchor: ClockAnchor


@dataclass(frozen=True)
class _FrameRecord:
    stamps: FrameStamps
    camera_gap: int
    pipeline_skipped: int


class LiveStatistics:
    """The sliding window of frame records and sends, and totals since the start.

    Thread-safe: the acquisition thread records frames, the event loop records sends.
    ``has_camera_counter`` says whether camera drops can be counted at all.
    """

    def __init__(
        self,
        *,
        window_s: float = DEFAULT_WINDOW_S,
        max_frames: int = DEFAULT_MAX_FRAMES,
        anchor: ClockAnchor | None = None,
    ) -> None:
        if not window_s > 0:
            raise ValueError(f"window_s must be > 0, got {window_s}")
        if max_frames < 1:
            raise ValueError(f"max_frames must be >= 1, got {max_frames}")
        self.window_s = window_s
        self.anchor = anchor or ClockAnchor.now()
        self._frames: deque[_FrameRecord] = deque(maxlen=max_frames)
        # (sent_ns, capture_to_sent_ms) per client message; clients times frames at most
        self._sends: deque[tuple[int, float]] = deque(maxlen=8 * max_frames)
        self._client_drops: deque[tuple[int, int]] = deque(maxlen=8 * max_frames)
        self._lock = threading.Lock()
        self._gaps = SequenceGaps()
        self.has_camera_counter = False
        self.frames_total = 0
        self.camera_dropped_total = 0
        self.pipeline_dropped_total = 0
        self.clients_dropped_total = 0

    def record_frame(
        self, stamps: FrameStamps, *, sequence: int | None, slots_skipped: int
    ) -> tuple[int, int]:
        """One frame through the pipeline; returns (camera gap, pipeline skipped) before
        it."""
        with self._lock:
            gap = self._gaps.observe(sequence)
            self.has_camera_counter = self.has_camera_counter or sequence is not None
            skipped = max(int(slots_skipped), 0)
            self._frames.append(_FrameRecord(stamps, gap, skipped))
            self.frames_total += 1
            self.camera_dropped_total += gap
            self.pipeline_dropped_total += skipped
            return gap, skipped

    def record_sent(self, stamps: FrameStamps, sent_ns: int) -> None:
        """One client's message for a frame handed to its socket at ``sent_ns``."""
        with self._lock:
            self._sends.append((sent_ns, stamps.capture_to_sent_ms(sent_ns)))

    def record_client_drops(self, n: int, *, now_ns: int | None = None) -> None:
        """``n`` more frames a client's mailbox dropped (the hub's ``dropped``)."""
        if n <= 0:
            return
        with self._lock:
            self._client_drops.append((now_ns or time.monotonic_ns(), n))
            self.clients_dropped_total += n

    def _forget_before(self, start_ns: int) -> None:
        """Drop what left the window (each deque is in time order; the lock is held)."""
        while self._frames and self._frames[0].stamps.arrival_ns < start_ns:
            self._frames.popleft()
        for timed in (self._sends, self._client_drops):
            while timed and timed[0][0] < start_ns:
                timed.popleft()

    def snapshot(self, now_ns: int | None = None) -> LatencySnapshot:
        """The statistics over the window ending at ``now_ns`` (monotonic ns; now)."""
        now_ns = time.monotonic_ns() if now_ns is None else now_ns
        start_ns = now_ns - int(self.window_s * 1e9)
        with self._lock:
            self._forget_before(start_ns)
            frames = [r for r in self._frames if r.stamps.arrival_ns >= start_ns]
            sent_ms = np.array([ms for t, ms in self._sends if t >= start_ns], float)
            client_drops = sum(n for t, n in self._client_drops if t >= start_ns)
            camera = self.has_camera_counter
            totals = DropCounts(
                self.camera_dropped_total if camera else None,
                self.pipeline_dropped_total,
                self.clients_dropped_total,
            )
            frames_total = self.frames_total
        arrival = np.array([r.stamps.capture_to_arrival_ms for r in frames], float)
        pose = np.array([r.stamps.capture_to_pose_ms for r in frames], float)
        in_window = DropCounts(
            sum(r.camera_gap for r in frames) if camera else None,
            sum(r.pipeline_skipped for r in frames),
            client_drops,
        )
        return LatencySnapshot(
            window_s=self.window_s,
            frames_in_window=len(frames),
            capture_to_arrival=LatencySummary.of(arrival),
            capture_to_pose=LatencySummary.of(pose),
            capture_to_sent=LatencySummary.of(sent_ms),
            dropped_in_window=in_window,
            dropped_total=totals,
            frames_total=frames_total,
            anchor=self.anchor,
        )


CAPTURE_SOURCES = {
    "sim": "the simulator's render time (lab clock mapped to the host's)",
    "replay": "the recording's own stamp mapped to playback time",
    "tofcam660": "the host's clock when the acquisition command went to the camera",
}
NO_CAPTURE_TIME = "arrival at the server (the driver gives no capture time)"


def capture_source(camera_name: str, capture_from_device: bool) -> str:
    """What a frame's capture stamp is on the camera ``camera_name`` (its driver's name),
    in words."""
    if not capture_from_device:
        return NO_CAPTURE_TIME
    return CAPTURE_SOURCES.get(camera_name, "the driver's capture time")
