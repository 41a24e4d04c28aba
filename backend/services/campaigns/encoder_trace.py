"""The motion system's encoders as a time series, for dynamic campaigns.

While a motion profile runs, a frame's reference is the encoder reading at the frame's
capture time, not the one read when the frame reached the server (a ToF frame arrives
tens of milliseconds after its exposure, and a slewing table has moved on by then).
``EncoderTrace`` polls the motion status in a thread of its own, keeps every reading
with its time stamp (``MotionStatus.time_s``: the clock of the camera's ``time_s``, the
lab clock on the simulator and the host's monotonic clock on real devices), and
interpolates the axes linearly to any time inside what it has read.
"""

from __future__ import annotations

import bisect
import logging
import threading
import time

from backend.drivers.base import MotionDriver, MotionStatus

log = logging.getLogger(__name__)


class EncoderTraceError(RuntimeError):
    """The motion system's readings cannot give a time series (no time stamps, or none
    read)."""


class EncoderTrace:
    """Encoder readings polled every ``period_s`` (s) from ``motion`` until ``stop``."""

    def __init__(self, motion: MotionDriver, period_s: float = 0.02) -> None:
        self.motion = motion
        self.period_s = period_s
        self._times: list[float] = []
        self._positions: list[dict[str, float]] = []
        self._latest: MotionStatus | None = None
        self._read_monotonic = time.monotonic()
        self._error: str = ""
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> EncoderTrace:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        """Read once now (``EncoderTraceError`` when the reading has no time stamp), then
        keep reading in the background."""
        st = self.motion.status()
        if st.time_s is None:
            raise EncoderTraceError(
                f"the {self.motion.name!r} motion system gives no time stamp with its "
                "encoder readings: a dynamic set-point needs them to reference each frame"
            )
        self._add(st)
        self._thread = threading.Thread(target=self._poll, name="encoder-trace", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _add(self, st: MotionStatus) -> None:
        with self._cond:
            self._latest = st
            self._read_monotonic = time.monotonic()
            self._error = ""
            if st.time_s is not None and (not self._times or st.time_s > self._times[-1]):
                self._times.append(float(st.time_s))
                self._positions.append(dict(st.positions))
            self._cond.notify_all()

    def _poll(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self._add(self.motion.status())
            except Exception as exc:  # the runner sees it as a gap, and the status as stale
                with self._cond:
                    self._error = str(exc)
                log.debug("encoder trace: status failed: %s", exc)

    @property
    def latest(self) -> MotionStatus:
        """The last status read (``start`` has read one)."""
        with self._cond:
            assert self._latest is not None
            return self._latest

    def stale_s(self) -> float:
        """Wall seconds since the last successful reading."""
        with self._cond:
            return time.monotonic() - self._read_monotonic

    @property
    def error(self) -> str:
        """The last failed reading's error since the last good one ("" when none)."""
        with self._cond:
            return self._error

    @property
    def n(self) -> int:
        with self._cond:
            return len(self._times)

    def at(self, time_s: float, wait_s: float = 1.0) -> dict[str, float] | None:
        """Axis positions at ``time_s``, linear between the two readings around it. Waits up
        to ``wait_s`` (wall time) for a reading after ``time_s`` (a frame stamped at its
        exposure is processed before the next reading is in); None when ``time_s`` lies
        before the first reading or no later reading came."""
        deadline = time.monotonic() + wait_s
        with self._cond:
            while not self._times or self._times[-1] < time_s:
                left = deadline - time.monotonic()
                if left <= 0 or self._stop.is_set():
                    return None
                self._cond.wait(min(left, self.period_s))
            k = bisect.bisect_left(self._times, time_s)
            if k == 0:
                return dict(self._positions[0]) if self._times[0] == time_s else None
            t0, t1 = self._times[k - 1], self._times[k]
            p0, p1 = self._positions[k - 1], self._positions[k]
        w = (time_s - t0) / (t1 - t0)
        return {a: p0[a] + w * (p1[a] - p0[a]) for a in p0 if a in p1}
