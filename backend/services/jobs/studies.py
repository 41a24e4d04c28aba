"""Accuracy studies run by the server (``tofpose.study``), one at a time, on Dask.

Each study lives in ``<data_dir>/studies/<id>/`` (the study store: ``study.json`` is the
source of truth for its status and progress, so a restarted server finds them again).
Studies queue in submission order and run in a background thread; a study that was
queued or running when the server stopped is queued again at start and resumes from the
chunks it had finished. The queue, the cluster and the start and stop are those of every
batch job (``batch_service``).

Limits (docs/scaleout.md): a study's size is checked from its axes before anything is
made (``study_limits``, ``tofpose.study.spec.StudyLimits``), and ``submit`` refuses a
study while ``max_active`` are queued or running (``TooManyStudiesError``). Reading a
study's status costs the same however large its grid: cells and frames are computed
from the axis lengths, the chunks are counted in ``study.json``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from backend.services.jobs.batch_queue import BatchQueue
from backend.services.jobs.batch_service import BatchJobService
from tofpose.study.spec import StudyLimits, StudySpec, StudySpecError
from tofpose.study.store import StudyStoreError, open_store, read_manifest, write_manifest

log = logging.getLogger(__name__)

REPORT_FILES = {"html": "report.html", "pdf": "report.pdf", "json": "summary.json"}
ACTIVE = ("created", "queued", "running")


class UnknownStudyError(LookupError):
    """No study with that id (the message says which)."""


class TooManyStudiesError(RuntimeError):
    """As many studies as allowed are queued or running; the message says how many and
    which setting sets the limit."""


def study_limits(settings) -> StudyLimits:
    """The server's limits on one study: ``settings.study_max_cells`` and
    ``study_max_frames`` (``backend.settings.Settings``), named by their variables."""
    return StudyLimits(
        max_cells=settings.study_max_cells,
        max_frames=settings.study_max_frames,
        source="TOFPOSE_STUDY_MAX_{what}",
    )


@dataclass(frozen=True)
class StudyStatus:
    """What ``GET /api/studies/{id}`` shows: the manifest's status and progress."""

    id: int
    name: str
    status: str
    cells: int
    frames_planned: int
    frames_done: int
    chunks: int
    chunks_done: int
    eta_s: float | None
    error: str | None
    started: str | None
    finished: str | None
    cluster: str | None
    reports: tuple[str, ...]
    #: the Dask dashboard while the study runs on a cluster, else None
    dashboard_url: str | None = None
    #: what slows its cluster down (more workers than cores), from its last run
    warnings: tuple[str, ...] = ()


class StudyService(BatchJobService):
    """Submit, list, follow and cancel studies (module docstring). ``jobs``: the queue
    they run on, shared with re-processing (``backend.services.jobs.batch_queue``); without
    one the service makes and owns its own."""

    kind = "study"

    def __init__(
        self,
        root: Path,
        scheduler: str | None = None,
        workers: int | None = None,
        jobs: BatchQueue | None = None,
    ) -> None:
        super().__init__(root, scheduler, workers, jobs)
        self._lock = threading.Lock()

    def _requeue(self, sid: int) -> bool:
        """A study a stopped server left queued or running resumes (its manifest still
        says so)."""
        try:
            return read_manifest(self._dir(sid))["status"] in ACTIVE
        except StudyStoreError:
            return False

    # -- commands ---------------------------------------------------------------------
    def submit(self, spec: StudySpec, max_active: int | None = None) -> int:
        """Store ``spec`` as a new study and queue it; returns its id.
        ``TooManyStudiesError`` (nothing stored) when ``max_active`` studies are already
        queued or running (None: no limit). Its size was checked when it was made
        (``StudySpec.from_dict``'s limits)."""
        with self._lock:
            if max_active is not None:
                active = self._active()
                if active >= max_active:
                    raise TooManyStudiesError(
                        f"{active} studies are queued or running, the limit is {max_active} "
                        "(TOFPOSE_STUDIES_MAX_ACTIVE): cancel one or wait for one to end"
                    )
            sid = max(self._ids(), default=0) + 1
            manifest = open_store(self._dir(sid), spec)
            manifest["status"] = "queued"
            write_manifest(self._dir(sid), manifest)
        self._enqueue(sid)
        return sid

    def cancel(self, sid: int) -> StudyStatus:
        """Stop a queued or running study; its finished chunks stay (``incomplete``)."""
        status = self.status(sid)
        if status.status in ACTIVE:
            with self._lock:
                if not self.jobs.cancel(self._key(sid)):  # queued: it will never run
                    m = read_manifest(self._dir(sid))
                    m["status"] = "incomplete"
                    write_manifest(self._dir(sid), m)
        return self.status(sid)

    # -- queries ----------------------------------------------------------------------
    def list(self) -> list[StudyStatus]:
        """Every study, newest first (unreadable directories left out)."""
        out = []
        for sid in sorted(self._ids(), reverse=True):
            try:
                out.append(self.status(sid))
            except (UnknownStudyError, StudyStoreError, StudySpecError):
                continue
        return out

    def status(self, sid: int) -> StudyStatus:
        """Study ``sid``'s status (``StudyStatus``), from its ``study.json``: the same cost
        for any size (nothing of its grid is made)."""
        d = self._dir(sid)
        if not (d / "study.json").exists():
            raise UnknownStudyError(f"no study with id {sid}")
        m = read_manifest(d)
        spec = StudySpec.from_dict(m["spec"], limits=None)  # accepted when it was stored
        reports = tuple(k for k, name in REPORT_FILES.items() if (d / name).exists())
        return StudyStatus(
            id=sid,
            name=spec.name,
            status=m["status"],
            cells=spec.n_cells,
            frames_planned=spec.n_frames,
            frames_done=m.get("frames_done", 0),
            chunks=m["chunks"],
            chunks_done=m.get("chunks_done", 0),
            eta_s=m.get("eta_s"),
            error=m.get("error"),
            started=m.get("started"),
            finished=m.get("finished"),
            cluster=m.get("cluster"),
            reports=reports,
            dashboard_url=self.dashboard_url(sid) if m["status"] == "running" else None,
            warnings=tuple(m.get("warnings") or ()),
        )

    def report_path(self, sid: int, kind: str) -> Path | None:
        """The study's report file of ``kind`` (``REPORT_FILES``), None before it exists."""
        self.status(sid)
        p = self._dir(sid) / REPORT_FILES[kind]
        return p if p.exists() else None

    # -- the runner -------------------------------------------------------------------
    def _run_one(self, sid: int, should_stop: Callable[[], bool]) -> None:
        """The job: run study ``sid`` to its end, or until ``should_stop``."""
        # imported by the first study, not with the server (docs/server.md, "Memory")
        from tofpose.study.run import StudyCancelledError, run_study

        try:
            spec = StudySpec.from_dict(read_manifest(self._dir(sid))["spec"], limits=None)
            run_study(
                spec,
                self._dir(sid),
                progress=False,
                should_stop=should_stop,
                on_cluster=partial(self._on_cluster, sid),
                **self._cluster(),
            )
        except StudyCancelledError:
            log.info("study %d stopped (its finished chunks are kept)", sid)
            if not self.jobs.is_cancelled(self._key(sid)):  # the server stops: resume later
                m = read_manifest(self._dir(sid))
                m["status"] = "queued"
                write_manifest(self._dir(sid), m)
        except Exception:  # noqa: BLE001 (the store says failed, with the error)
            log.exception("study %d failed", sid)

    def _active(self) -> int:
        """How many studies are queued or running (their ``study.json`` says so)."""
        n = 0
        for sid in self._ids():
            try:
                n += read_manifest(self._dir(sid))["status"] in ACTIVE
            except StudyStoreError:
                continue
        return n
