"""The Dask cluster a study or a re-processing runs on.

No address: a ``LocalCluster`` of worker processes on this machine, on loopback, one
thread each (the pipeline is single-threaded per frame; processes sidestep the GIL).
An address (``tcp://host:8786``): an existing scheduler, e.g. ``dask scheduler`` and
``dask worker`` started on lab machines, or a dask-jobqueue / dask-kubernetes cluster's.
Workers must run the same tofpose version as the client (checked on connecting).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

CONNECT_TIMEOUT_S = 10.0


class ClusterError(RuntimeError):
    """The cluster cannot be used; the message names the address or the worker."""


def default_workers(reserve: int = 0) -> int:
    """Worker processes for a LocalCluster: the cores this process may use, less
    ``reserve`` (e.g. one for a live camera loop), at least 1."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, cores - reserve)


def _lower_priority(niceness: int) -> int:
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


def _worker_info() -> dict:
    import tofpose

    return {"tofpose": tofpose.__version__, "pid": os.getpid()}


@contextmanager
def dask_client(
    workers: int | None = None, scheduler: str | None = None, niceness: int = 0
) -> Iterator:
    """A ``distributed.Client``: on ``scheduler`` when given, else on a LocalCluster of
    ``workers`` processes (``default_workers()`` when None) whose scheduling priority is
    lowered by ``niceness`` (``os.nice``: a server's live loop keeps its core when a
    study competes for it). ``ClusterError`` naming the
    address when the scheduler cannot be reached, naming the worker when one runs
    another tofpose version. Closes what it started."""
    from dask.distributed import Client, LocalCluster

    import tofpose

    if workers is not None and workers < 1:
        raise ClusterError(f"--workers must be >= 1 (got {workers})")
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    else:
        cluster = LocalCluster(
            n_workers=workers or default_workers(),
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
        if niceness:
            client.run(_lower_priority, niceness)
    try:
        if scheduler:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        for address, info in client.run(_worker_info).items():
            if info["tofpose"] != tofpose.__version__:
                raise ClusterError(
                    f"worker {address} runs tofpose {info['tofpose']}, this client "
                    f"{tofpose.__version__}: install the same version on every worker"
                )
        yield client
    except TimeoutError as exc:
        raise ClusterError(f"the Dask scheduler at {scheduler} has no workers ({exc})") from exc
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
