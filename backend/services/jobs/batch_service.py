"""What the server's two kinds of batch job (accuracy studies, re-processing) share: a
directory per job under one root, the Dask cluster they run on, the batch queue, and the
start and stop of the service.

A job is named by its id, the name of its directory (``<root>/<id>/``), and on the queue
by ``(kind, id)``. A service given a queue (the server's, shared by both kinds) leaves
starting and stopping it to its owner; one made without makes and owns its own. The
cluster: ``scheduler`` (``TOFPOSE_DASK_SCHEDULER``) when set, else a LocalCluster of
``workers`` (the cores less one: the live camera loop keeps its core) whose workers run at
a lower priority (``WORKER_NICENESS``), so a job takes what the live loop leaves.

While a job runs on a cluster the service keeps that cluster's session in memory
(``_on_cluster``): ``dashboard_url(id)`` is the Dask dashboard's address then, None
otherwise (after a restart no cluster runs). A cluster's warnings (more workers than
cores, ``tofpose.batch.cluster.ClusterWarning``) are stored with the job's status.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, ClassVar

from backend.services.jobs.batch_queue import BatchQueue
from tofpose.batch.cluster import ClusterSession, default_workers

WORKER_NICENESS = 10


class BatchJobService(ABC):
    """The common part of ``StudyService`` and ``ReprocessService`` (module docstring).
    A subclass names its ``kind``, says which stored jobs a restarted server queues again
    (``_requeue``) and runs one job (``_run_one``)."""

    #: the first part of a job's key on the queue, e.g. ``("study", 3)``
    kind: ClassVar[str]

    def __init__(
        self,
        root: Path,
        scheduler: str | None = None,
        workers: int | None = None,
        jobs: BatchQueue | None = None,
    ) -> None:
        self.root = Path(root)
        self.scheduler = scheduler or None
        self.workers = workers if workers is not None else default_workers(reserve=1)
        self._own_jobs = jobs is None
        self.jobs = jobs if jobs is not None else BatchQueue()
        self._sessions: dict[int, ClusterSession] = {}
        self._sessions_lock = threading.Lock()

    # -- lifecycle --------------------------------------------------------------------
    def start(self) -> int:
        """Queue again the jobs a stopped server left queued or running (``_requeue``
        says which), and start the queue when the service owns it. Returns how many
        were queued again."""
        self.root.mkdir(parents=True, exist_ok=True)
        again = 0
        for jid in sorted(self._ids()):
            if self._requeue(jid):
                self._enqueue(jid)
                again += 1
        if self._own_jobs:
            self.jobs.start()
        return again

    def stop(self) -> None:
        """End the queue when the service owns it: a running job sees ``should_stop``
        turn true and stays resumable."""
        if self._own_jobs:
            self.jobs.stop()

    # -- what a subclass says -----------------------------------------------------------
    @abstractmethod
    def _requeue(self, jid: int) -> bool:
        """Whether stored job ``jid`` is queued again at start (its store updated to
        say so where needed)."""

    @abstractmethod
    def _run_one(self, jid: int, should_stop: Callable[[], bool]) -> None:
        """The job: run ``jid`` to its end, or until ``should_stop()``."""

    # -- shared helpers ---------------------------------------------------------------
    def _key(self, jid: int) -> tuple[str, int]:
        return (self.kind, jid)

    def _enqueue(self, jid: int) -> None:
        self.jobs.put(self._key(jid), partial(self._run_one, jid))

    def _cluster(self) -> dict[str, Any]:
        """The cluster arguments of ``tofpose.batch`` and ``tofpose.study`` runs: the
        scheduler's address, or a LocalCluster's size and its workers' niceness."""
        return {
            "workers": None if self.scheduler else self.workers,
            "scheduler": self.scheduler,
            "niceness": 0 if self.scheduler else WORKER_NICENESS,
        }

    def dashboard_url(self, jid: int) -> str | None:
        """The Dask dashboard of the cluster job ``jid`` runs on; None when it runs on
        none (queued, finished, or between its cluster's start and stop)."""
        with self._sessions_lock:
            session = self._sessions.get(jid)
        return session.dashboard_url if session is not None else None

    def _on_cluster(self, jid: int, session: ClusterSession | None) -> None:
        """Job ``jid``'s cluster is up (``session``) or closed (None)."""
        with self._sessions_lock:
            if session is None:
                self._sessions.pop(jid, None)
            else:
                self._sessions[jid] = session

    def _dir(self, jid: int) -> Path:
        return self.root / str(jid)

    def _ids(self) -> list[int]:
        if not self.root.is_dir():
            return []
        return [int(p.name) for p in self.root.iterdir() if p.name.isdigit()]
