"""Frame pacing shared by drivers that produce frames on a clock (simulator, replay)."""

from __future__ import annotations

import threading
import time


class FramePacer:
    """Releases one frame per period; never builds a backlog when the reader is slow."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self._next_due: float | None = None
        self._closed = threading.Event()

    def set_rate(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz

    def close(self) -> None:
        self._closed.set()

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def wait(self, timeout_s: float) -> None:
        """Sleep until the next frame is due; ``TimeoutError`` if that is beyond timeout."""
        now = time.monotonic()
        due = now if self._next_due is None else self._next_due
        wait_s = due - now
        if wait_s > timeout_s:
            self._closed.wait(timeout_s)
            raise TimeoutError(f"no frame within {timeout_s:g} s")
        if wait_s > 0 and self._closed.wait(wait_s):
            raise TimeoutError("driver closed")
        if self._closed.is_set():
            raise TimeoutError("driver closed")
        self._next_due = max(due + 1.0 / self.rate_hz, time.monotonic())
