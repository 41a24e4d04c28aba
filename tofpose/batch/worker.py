"""What a Dask worker runs besides the tasks: its description for the client, its
priority, the glibc setting Dask's nanny gets wrong for frame-sized arrays, and the
progress a task reports while it runs. The forkserver of a LocalCluster imports this
module first (``tofpose.batch.cluster.PRELOAD``).

Progress: a task calls the ``ProgressReporter`` it is given after each frame; at most
every ``PROGRESS_INTERVAL_S`` (and after its first frame) it logs an event on the
run's own topic with the frames it has done (``distributed.Worker.log_event``), and the
client, subscribed to that topic, adds them up. Outside a worker (a task called
directly) it does nothing.
"""

from __future__ import annotations

import os
import socket
import time
from contextlib import suppress
from pathlib import Path

#: the longest a running task waits before it reports its frames again
PROGRESS_INTERVAL_S = 0.5
#: glibc's mallopt parameters and what ``relax_malloc_trim`` sets them to: what glibc's
#: own adaptive thresholds grow to (the mmap threshold's ceiling is 32 MB on 64-bit)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024


def worker_info() -> dict:
    """This worker's tofpose version, process id, host, cores and threads."""
    import tofpose

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    threads = 1
    with suppress(ImportError, ValueError):
        from distributed import get_worker

        threads = get_worker().state.nthreads
    return {
        "tofpose": tofpose.__version__,
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "cores": cores,
        "threads": threads,
    }


def lower_priority(niceness: int) -> int:
    """In a worker: raise every thread's nice value by ``niceness`` (on Linux a nice
    value is per thread; threads started later inherit their creator's). Returns the
    threads changed."""
    tasks = Path("/proc/self/task")
    tids = [int(t.name) for t in tasks.iterdir()] if tasks.is_dir() else [0]
    for tid in tids:
        # a thread that ended meanwhile, or not a POSIX system
        with suppress(OSError, AttributeError):
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + niceness)
    return len(tids)


def relax_malloc_trim() -> bool:
    """Undo Dask's ``MALLOC_TRIM_THRESHOLD_`` in a running worker (``tofpose.batch.cluster``
    explains the cost): glibc's trim and mmap thresholds set to where its adaptive ones
    would grow. True when the variable was set and glibc took the new values."""
    if "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return False
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
    except OSError:  # not glibc
        return False
    ok = libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
    ok &= libc.mallopt(_M_TRIM_THRESHOLD, 2 * _MMAP_THRESHOLD_BYTES)
    return bool(ok)


class ProgressReporter:
    """Called with the frames a task has done so far (module docstring); ``topic``:
    the run's event topic, ``key``: the task's name in the run, None for no reports."""

    def __init__(self, topic: str | None, key: str) -> None:
        self.key = key
        self.topic = topic or ""
        self._worker = None
        self._last = -float("inf")
        if topic:
            with suppress(ImportError, ValueError):  # not in a worker: no reports
                from distributed import get_worker

                self._worker = get_worker()

    def __call__(self, frames_done: int) -> None:
        if self._worker is None:
            return
        now = time.monotonic()
        if now - self._last >= PROGRESS_INTERVAL_S:
            self._last = now
            self._worker.log_event(self.topic, {"key": self.key, "frames": frames_done})
