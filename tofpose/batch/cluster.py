"""The Dask cluster a study or a re-processing runs on.

No address: a ``LocalCluster`` of worker processes on this machine, on loopback, one
thread each (the pipeline is single-threaded per frame; processes sidestep the GIL).
An address (``tcp://host:8786``): an existing scheduler, e.g. ``dask scheduler`` and
``dask worker`` started on lab machines, or a dask-jobqueue / dask-kubernetes cluster's.
Workers must run the same tofpose version as the client (checked on connecting).

How a LocalCluster's workers are made (each measured in ``bench/scaleout.py``):

- **their environment** (``WORKER_ENVIRONMENT``): one thread for OpenMP, MKL, OpenBLAS
  and numba (a worker is one process per core; the pipeline's matrices are 3x3 to 6x6),
  and *not* Dask's ``MALLOC_TRIM_THRESHOLD_=65536``. Setting that variable fixes glibc's
  mmap threshold at 128 kB, so every frame-sized array (a 320 x 240 image is 300-600 kB)
  is mapped and unmapped again at each allocation: 60-78 thousand page faults per
  8-frame study chunk against ~10 without, +70 % CPU per study frame and +30 % per
  re-processed frame. Workers of an external scheduler get the same fix at connection
  (``tofpose.batch.worker.relax_malloc_trim``, a no-op where the variable is unset).
- **how they start**: from a ``forkserver`` that imported the task modules and loaded
  the pipeline's kernels from numba's on-disk cache once (``PRELOAD``,
  ``tofpose.batch.warm_worker``), so a worker is a fork of a process that has numpy,
  numba, the pipeline, its kernels and distributed loaded, not a fresh interpreter that
  imports them again (and with ``spawn``, the caller's main module too) and then loads
  the kernels itself (``cache_misses`` in ``study.json``: none compiled).
- **the dashboard**: on a free loopback port; ``dashboard_url`` gives its address.

``ClusterWarning``: more worker threads on a host than it has cores (they share the
cores, so each runs slower than a serial run would); the session lists them too.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import time
import warnings
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

CONNECT_TIMEOUT_S = 10.0

#: a LocalCluster worker's environment, set before its process starts; None removes a
#: variable Dask would set (module docstring)
WORKER_ENVIRONMENT: dict[str, str | None] = {
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
    "MALLOC_TRIM_THRESHOLD_": None,
}
#: what the forkserver imports once, so that every worker forked from it has it
PRELOAD = (
    "tofpose.batch.worker",
    "tofpose.batch.reprocess",
    "tofpose.study.frames",
    "tofpose.batch.warm_worker",
)


class ClusterError(RuntimeError):
    """The cluster cannot be used; the message names the address or the worker."""


class ClusterWarning(UserWarning):
    """The cluster runs, but slower than it could (more workers than cores)."""


@dataclass(frozen=True)
class ClusterSession:
    """A connected cluster: ``client`` (``distributed.Client``), its worker count, the
    dashboard's address (None when the scheduler serves none), the warnings about it
    (``ClusterWarning``'s messages), the seconds it took to start and connect, and
    whether a task may read ahead in a thread of its own (``read_ahead``:
    ``spare_core_per_thread``)."""

    client: Any
    workers: int
    dashboard_url: str | None
    warnings: tuple[str, ...]
    start_s: float
    read_ahead: bool = False


def default_workers(reserve: int = 0) -> int:
    """Worker processes for a LocalCluster: the cores this process may use, less
    ``reserve`` (e.g. one for a live camera loop), at least 1."""
    return max(1, _cores() - reserve)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _threads_and_cores(workers: list[dict]) -> tuple[dict[str, int], dict[str, int]]:
    """Per host: its workers' threads and its cores (``worker_info`` of each worker)."""
    threads: dict[str, int] = defaultdict(int)
    cores: dict[str, int] = {}
    for w in workers:
        threads[w["host"]] += w["threads"]
        cores[w["host"]] = w["cores"]
    return threads, cores


def oversubscription_warnings(workers: list[dict]) -> list[str]:
    """One sentence per host whose workers have more threads than the host has cores;
    ``workers``: ``tofpose.batch.worker.worker_info`` of each worker (host, cores,
    threads)."""
    threads, cores = _threads_and_cores(workers)
    return [
        f"{threads[h]} worker threads on {h}, which has {cores[h]} cores: they share the "
        f"cores, so each runs slower than a serial run (use at most {cores[h]} workers there)"
        for h in sorted(threads)
        if threads[h] > cores[h]
    ]


def spare_core_per_thread(workers: list[dict]) -> bool:
    """Whether every host has at least two cores per worker thread, so that a task's
    reader thread (``tofpose.io.read_ahead``) runs beside it instead of taking turns with
    another worker's task on the same core (on 2 cores, two workers each reading ahead
    ran at 0.47x a serial run's frames/s per worker, one worker at 0.84x);
    ``workers`` as in ``oversubscription_warnings``."""
    threads, cores = _threads_and_cores(workers)
    return bool(threads) and all(cores[h] >= 2 * threads[h] for h in threads)


def dashboard_url(client) -> str | None:
    """The scheduler's dashboard, or (without bokeh, which draws it) the pages Dask
    serves without it (workers, their tasks and logs); None when it serves no HTTP."""
    link = client.dashboard_link
    if not link:
        return None
    if importlib.util.find_spec("bokeh") is None:  # the dashboard's plots
        return link.removesuffix("/status") + "/info/main/workers.html"
    return link


def _local_cluster(workers: int):
    """A LocalCluster of ``workers`` processes forked from a preloaded forkserver, with
    ``WORKER_ENVIRONMENT`` (module docstring)."""
    import dask
    from dask.distributed import LocalCluster
    from distributed.utils import get_mp_context

    environ = {
        **dask.config.get("distributed.nanny.pre-spawn-environ"),
        **WORKER_ENVIRONMENT,
    }
    for name, value in WORKER_ENVIRONMENT.items():
        if value is None:  # a nanny of an earlier cluster may have set it in this process
            os.environ.pop(name, None)
    with dask.config.set(
        {
            "distributed.worker.multiprocessing-method": "forkserver",
            "distributed.nanny.pre-spawn-environ": environ,
        }
    ):
        # Dask sets its own preload list (distributed and its dependencies) on the first
        # call; this one replaces it with distributed and the task modules, which import
        # the rest
        get_mp_context().set_forkserver_preload(["distributed", *PRELOAD])
        return LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.ERROR,
        )


@contextmanager
def open_cluster(
    workers: int | None = None, scheduler: str | None = None, niceness: int = 0
) -> Iterator[ClusterSession]:
    """A ``ClusterSession``: on ``scheduler`` when given, else on a LocalCluster of
    ``workers`` processes (``default_workers()`` when None) whose scheduling priority is
    lowered by ``niceness`` (a server's live loop keeps its core when a study competes
    for it). ``ClusterError`` naming the address when the scheduler cannot be reached,
    naming the worker when one runs another tofpose version; a ``ClusterWarning`` for
    each host with more worker threads than cores. Closes what it started."""
    from dask.distributed import Client

    import tofpose
    from tofpose.batch.worker import lower_priority, relax_malloc_trim, worker_info

    if workers is not None and workers < 1:
        raise ClusterError(f"--workers must be >= 1 (got {workers})")
    t0 = time.perf_counter()
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    else:
        cluster = _local_cluster(workers or default_workers())
        client = Client(cluster)
        if niceness:
            client.run(lower_priority, niceness)
    try:
        if scheduler:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        # a no-op where the variable is not set (our LocalCluster's workers, unless this
        # process's forkserver started before with it)
        client.run(relax_malloc_trim)
        infos = client.run(worker_info)
        for address, info in infos.items():
            if info["tofpose"] != tofpose.__version__:
                raise ClusterError(
                    f"worker {address} runs tofpose {info['tofpose']}, this client "
                    f"{tofpose.__version__}: install the same version on every worker"
                )
        said = tuple(oversubscription_warnings(list(infos.values())))
        for message in said:
            warnings.warn(message, ClusterWarning, stacklevel=3)
        yield ClusterSession(
            client=client,
            workers=len(infos),
            dashboard_url=dashboard_url(client),
            warnings=said,
            start_s=time.perf_counter() - t0,
            read_ahead=spare_core_per_thread(list(infos.values())),
        )
    except TimeoutError as exc:
        raise ClusterError(f"the Dask scheduler at {scheduler} has no workers ({exc})") from exc
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, niceness: int = 0):
    """``open_cluster``'s ``distributed.Client`` alone."""
    with open_cluster(workers, scheduler, niceness) as session:
        yield session.client


@contextmanager
def session_or_open(
    session: ClusterSession | None,
    workers: int | None = None,
    scheduler: str | None = None,
    niceness: int = 0,
) -> Iterator[ClusterSession]:
    """``session`` when given (the caller's: left open), else ``open_cluster``'s."""
    if session is not None:
        yield session
        return
    with open_cluster(workers, scheduler, niceness) as own:
        yield own
