"""The pipeline's compiled kernels, made ready in a background thread at server start.

On a fresh install numba compiles every kernel on first use (about 1-2 min on 2 cores);
later starts load them from numba's on-disk cache in a few seconds. The server does not
wait for that: the camera loop streams frames at once, and poses follow when
``KernelWarmup.ready`` is set (``GET /api/health`` -> ``pipeline``; the dashboard's
device panel shows it). ``tofpose.warmup.warm_up`` runs the pipeline through every
compiled path once, so nothing compiles later in the live loop.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Literal

from tofpose.warmup import warm_up

log = logging.getLogger(__name__)

COMPILING_REASON = (
    "pipeline kernels compiling (first start after an install): frames stream, poses follow"
)


class KernelWarmup:
    """Runs ``warm_up`` once, in a daemon thread (``start``) or inline (``run``).

    state : "compiling" until it finishes, then "ready" (or "failed": the pipeline still
    runs, compiling on first use). seconds : how long it took (None while compiling).
    """

    def __init__(self) -> None:
        self.ready = threading.Event()
        self.state: Literal["compiling", "ready", "failed"] = "compiling"
        self.error = ""
        self.seconds: float | None = None
        self._t0 = time.monotonic()
        self._thread: threading.Thread | None = None

    @property
    def elapsed_s(self) -> float:
        """Seconds since the warm-up started (its duration once finished)."""
        return self.seconds if self.seconds is not None else time.monotonic() - self._t0

    def start(self) -> None:
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self.run, name="kernel-warmup", daemon=True)
        self._thread.start()

    def run(self) -> None:
        self._t0 = time.monotonic()
        try:
            warm_up()
            self.state = "ready"
        except Exception as exc:  # the live pipeline compiles on first use instead
            log.exception("warming up the pipeline kernels failed")
            self.state, self.error = "failed", f"kernel warm-up failed: {exc}"
        finally:
            self.seconds = time.monotonic() - self._t0
            self.ready.set()
        if self.seconds > 5:
            log.info("pipeline kernels ready after %.0f s (compiled; numba caches them)",
                     self.seconds)  # fmt: skip

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the warm-up; True when it has finished."""
        return self.ready.wait(timeout_s)
