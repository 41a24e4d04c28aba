"""One background thread that runs the server's batch jobs (accuracy studies,
re-processing of campaign recordings) one at a time, in submission order.

Both kinds run on the same Dask cluster (``TOFPOSE_DASK_SCHEDULER``, or a LocalCluster of
the cores the live camera loop leaves); running them one after the other keeps two
LocalClusters from competing for those cores. A job is a callable that takes
``should_stop() -> bool`` and returns when done or when ``should_stop`` says so; a job
is named by a key such as ``("study", 3)``.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable, Hashable

log = logging.getLogger(__name__)

Job = Callable[[Callable[[], bool]], None]


class BatchQueue:
    """The queue and its runner thread (module docstring)."""

    def __init__(self) -> None:
        self._queue: queue.Queue[tuple[Hashable, Job] | None] = queue.Queue()
        self._cancelled: set[Hashable] = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._running: Hashable | None = None

    def start(self) -> None:
        """Start the runner thread (once; later calls do nothing)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="batch-jobs", daemon=True)
            self._thread.start()

    def stop(self, timeout_s: float = 60.0) -> None:
        """Ask the running job to stop (``should_stop`` turns true) and end the runner."""
        self._stopping.set()
        self._queue.put(None)
        if self._thread is not None:
            self._thread.join(timeout=timeout_s)

    @property
    def stopping(self) -> bool:
        """True once ``stop`` was called: a job that stops now should resume later."""
        return self._stopping.is_set()

    def put(self, key: Hashable, job: Job) -> None:
        """Queue ``job`` under ``key``."""
        self._queue.put((key, job))

    def cancel(self, key: Hashable) -> bool:
        """Cancel the job ``key``: a queued one never runs, a running one sees
        ``should_stop`` turn true. Returns True when it is running now."""
        with self._lock:
            self._cancelled.add(key)
            return self._running == key

    def is_cancelled(self, key: Hashable) -> bool:
        with self._lock:
            return key in self._cancelled

    def _run(self) -> None:
        while not self._stopping.is_set():
            item = self._queue.get()
            if item is None:
                return
            key, job = item
            with self._lock:
                if key in self._cancelled:
                    self._cancelled.discard(key)
                    continue
                self._running = key

            def should_stop(key: Hashable = key) -> bool:
                return self._stopping.is_set() or self.is_cancelled(key)

            try:
                job(should_stop)
            except Exception:  # noqa: BLE001 (each job records its own failure)
                log.exception("batch job %s failed", key)
            finally:
                with self._lock:
                    self._running = None
                    self._cancelled.discard(key)
