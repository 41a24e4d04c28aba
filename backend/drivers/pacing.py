"""Frame pacing shared by drivers that produce frames on a clock (simulator, replay,
the TOFcam-660's single-shot acquisitions)."""

from __future__ import annotations

import math
import threading
import time


class FramePacer:
    """Releases one frame per period; never builds a backlog when the reader is slow.

    ``wait`` returns how many frames the rate offered since the previous release that
    the reader was too busy to take: the release times are counted in slots of one
    period from the first release (a camera running freely at ``rate_hz`` would have
    delivered one frame per slot), and each slot between two releases is a frame
    skipped (``CameraFrame.slots_skipped``: the pipeline's dropped frames).
    """

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self._next_due: float | None = None
        self._closed = threading.Event()
        self._slot_origin_s: float | None = None
        self._last_slot = 0

    def set_rate(self, rate_hz: float) -> None:
        if rate_hz != self.rate_hz:
            self._slot_origin_s = None  # slots of the new period start at the next release
        self.rate_hz = rate_hz

    def _slots_skipped(self, now_s: float) -> int:
        """Slots passed since the last release, minus the one released now."""
        if self._slot_origin_s is None:
            self._slot_origin_s, self._last_slot = now_s, 0
            return 0
        slot = math.floor((now_s - self._slot_origin_s) * self.rate_hz + 1e-6)
        skipped = max(slot - self._last_slot - 1, 0)
        self._last_slot = max(slot, self._last_slot)
        return skipped

    def close(self) -> None:
        self._closed.set()

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def wait(self, timeout_s: float) -> int:
        """Sleep until the next frame is due; ``TimeoutError`` if that is beyond timeout.
        Returns the frames skipped since the previous release (class docstring)."""
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
        released = time.monotonic()
        self._next_due = max(due + 1.0 / self.rate_hz, released)
        return self._slots_skipped(released)
