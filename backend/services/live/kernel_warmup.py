"""The pipeline's compiled kernels, made ready in a background thread at server start.

On a fresh install numba compiles every kernel on first use (about 1-2 min on 2 cores);
later starts load them from numba's on-disk cache in a few seconds. The server does not
wait for that: the warm-up (``tofpose.warmup``) first compiles the few kernels that the
reference implementation of the pipeline still calls (``warm_up_reference``, about 1 s;
``reference_ready``), and the acquisition loop measures with that implementation
(NumPy/SciPy, the same poses to ~0.01 mm) while the rest compiles (``warm_up``; ``ready``),
then switches to the compiled one (``backend/services/live/acquisition.py``). ``GET
/api/health`` -> ``pipeline`` says which runs; the dashboard's device panel shows it.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Literal

from tofpose.warmup import warm_up, warm_up_reference

log = logging.getLogger(__name__)

#: a frame's reason while not even the reference pipeline can run yet (the first stage)
COMPILING_REASON = (
    "pipeline kernels compiling (first start after an install): frames stream, poses follow"
)
#: what ``pipeline.detail`` says while the reference implementation gives the poses
REFERENCE_DETAIL = (
    "poses from the reference implementation (NumPy/SciPy) while the kernels compile "
    "(first start after an install: about 2 min)"
)


class KernelWarmup:
    """Runs the warm-up once, in a daemon thread (``start``) or inline (``run``).

    reference_ready : set when the reference pipeline's kernels are compiled (it then
        compiles nothing), before ``ready``; also set when that stage fails (the
        reference pipeline then compiles those few small kernels on first use).
    ready : set when the whole warm-up has finished (or failed).
    state : "compiling" until it finishes, then "ready" (or "failed": the live loop
        keeps the reference implementation rather than compile in its own thread).
    seconds : how long it took (None while compiling).
    """

    def __init__(self) -> None:
        self.reference_ready = threading.Event()
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
            try:
                warm_up_reference()  # what the live loop needs first
            finally:
                self.reference_ready.set()
            warm_up()
            self.state = "ready"
        except Exception as exc:
            log.exception("warming up the pipeline kernels failed")
            self.state, self.error = "failed", f"kernel warm-up failed: {exc}"
        finally:
            self.seconds = time.monotonic() - self._t0
            self.ready.set()
        if self.state == "ready" and self.seconds > 5:
            log.info(
                "pipeline kernels ready after %.0f s (compiled; numba caches them)", self.seconds
            )

    def join(self, timeout_s: float | None = None) -> bool:
        """Wait for the warm-up; True when it has finished."""
        return self.ready.wait(timeout_s)
