"""Long work that a request waits for (rendering a report, exporting a recording to
MCAP): on a few threads of its own, with a bounded wait queue.

Before, such requests were sync routes on AnyIO's shared 40-thread pool: 60 MCAP
downloads filled it and every other sync request (and, before STOP became async, STOP)
waited until an export finished. Now a route awaits ``HeavyWork.run``: at most
``workers`` jobs run at once (an AnyIO ``CapacityLimiter`` of its own, so waiting
holds no thread), at most ``max_waiting`` more wait, and a request beyond that is
refused at once with ``HeavyWorkBusyError`` (the API answers 503 with ``Retry-After``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import anyio
import anyio.to_thread

T = TypeVar("T")


class HeavyWorkBusyError(RuntimeError):
    """Every worker is busy and the wait queue is full; ``retry_after_s`` a hint."""

    def __init__(self, message: str, retry_after_s: int) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


class HeavyWork:
    """At most ``workers`` jobs at once and ``max_waiting`` waiting (one per app)."""

    def __init__(self, workers: int = 2, max_waiting: int = 8) -> None:
        if workers < 1 or max_waiting < 0:
            raise ValueError(
                f"workers must be >= 1 and max_waiting >= 0, got {workers}, {max_waiting}"
            )
        self.workers = workers
        self.max_waiting = max_waiting
        self._limiter: anyio.CapacityLimiter | None = None  # made on the event loop
        self._admitted = 0  # running + waiting (only touched on the event loop)

    @property
    def admitted(self) -> int:
        """Jobs running or waiting now."""
        return self._admitted

    async def run(self, work: Callable[[], T], what: str) -> T:
        """Run ``work`` on a worker thread and return its result; ``HeavyWorkBusyError`` at once
        when ``workers + max_waiting`` jobs are already admitted (``what``: for the
        message, e.g. "the PDF report")."""
        if self._limiter is None:
            self._limiter = anyio.CapacityLimiter(self.workers)
        if self._admitted >= self.workers + self.max_waiting:
            raise HeavyWorkBusyError(
                f"the server is busy with {self._admitted} reports and exports "
                f"({self.workers} at a time, {self.max_waiting} waiting): {what} was not "
                "started, try again shortly",
                retry_after_s=5,
            )
        self._admitted += 1
        try:
            return await anyio.to_thread.run_sync(work, limiter=self._limiter)
        finally:
            self._admitted -= 1
