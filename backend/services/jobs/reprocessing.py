"""Re-processing of a stored campaign's recording with another camera calibration, run
by the server on Dask (``tofpose.batch.reprocess``; docs/scaleout.md).

A job re-runs the pipeline over ``campaign-<id>.h5`` twice, on the batch queue the
studies use (one job at a time, workers at a lower priority): once with the camera JSON
the request gave (intrinsics, and the ``range_correction`` / ``covariance_scale`` that
``tofpose calibrate-range`` and ``calibrate-covariance`` add), and once with the camera
the recording was made with (the baseline), then compares them frame by frame
(``tofpose.batch.compare``: B = the new calibration, A = the baseline). Each job lives in
``<data_dir>/reprocessings/<id>/``: ``job.json`` (the source of truth for its status, so a
restarted server finds it again), ``camera.json``, ``run/`` and ``baseline/`` (each a
``tofpose reprocess`` directory: ``campaign-<id>.csv`` is what ``tofpose estimate``
writes), and ``compare.csv|json|png``. Both passes run on one cluster (started once
per job); while they run, the status carries the Dask dashboard's address
(``dashboard_url``) and the frames done so far over both passes (``frames_done`` of
``frames_planned``, reported by the running chunks), and the cluster's warnings (more
workers than cores) are stored with the job.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import threading
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from functools import partial
from pathlib import Path

from backend.services.jobs.batch_queue import BatchQueue
from backend.services.jobs.batch_service import BatchJobService
from tofpose.batch.cluster import open_cluster
from tofpose.batch.reprocess import ReprocessCancelledError, Settings, reprocess
from tofpose.io.camera_file import load_camera
from tofpose.io.recording import RecordingError, open_recording

log = logging.getLogger(__name__)

STATES = ("queued", "running", "complete", "failed", "cancelled")
# files a client may download, by name: the new calibration's poses, the baseline's, the comparison
FILES = {
    "poses.csv": ("run", "text/csv"),
    "baseline.csv": ("baseline", "text/csv"),
    "compare.csv": ("compare.csv", "text/csv"),
    "compare.json": ("compare.json", "application/json"),
    "compare.png": ("compare.png", "image/png"),
}


class UnknownReprocessingError(LookupError):
    """No re-processing with that id (the message says which)."""


class ReprocessRequestError(ValueError):
    """A request that cannot run; ``field`` names the request field, the message why."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _write_json(path: Path, doc: dict) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    tmp.write_text(json.dumps(doc, indent=2))
    os.replace(tmp, path)


def check_camera(camera: dict, recording: Path) -> str:
    """The camera JSON text for ``recording``'s frames; ``ReprocessRequestError`` naming
    the field when it is not a camera (``tofpose.core.camera.CameraModel``) or its image size
    differs from the recording's."""
    text = json.dumps(camera)
    try:
        model, _, _ = load_camera(text)
    except Exception as exc:  # noqa: BLE001 (any field of any JSON type may be wrong)
        raise ReprocessRequestError("camera", f"not a camera JSON: {exc}") from exc
    with open_recording(recording) as rec:
        if model.shape != rec.camera.shape:
            raise ReprocessRequestError(
                "camera",
                f"camera {model.width}x{model.height} does not match the "
                f"recording's {rec.camera.width}x{rec.camera.height} frames",
            )
    return text


class ReprocessService(BatchJobService):
    """Submit, list, follow and cancel re-processing jobs (module docstring; the queue,
    the cluster and the start and stop: ``batch_service``)."""

    kind = "reprocess"

    def __init__(
        self,
        root: Path,
        scheduler: str | None = None,
        workers: int | None = None,
        jobs: BatchQueue | None = None,
    ) -> None:
        super().__init__(root, scheduler, workers, jobs)
        self._lock = threading.Lock()
        # job id -> (frames done, frames planned) over both passes, while it runs
        self._progress: dict[int, tuple[int, int]] = {}

    def _requeue(self, jid: int) -> bool:
        """A job a stopped server left queued or running starts over (a job is a few
        passes over one recording): stored as queued again."""
        job = self._read(jid)
        if job is None or job["status"] not in ("queued", "running"):
            return False
        job["status"] = "queued"
        _write_json(self._dir(jid) / "job.json", job)
        return True

    # -- commands ---------------------------------------------------------------------
    def submit(
        self,
        campaign_id: int,
        recording: Path,
        camera: dict | None,
        *,
        tracking: bool = False,
        filter_state: bool = False,
    ) -> dict:
        """Store and queue a job over ``recording`` (campaign ``campaign_id``'s) with
        ``camera`` (a camera JSON object; None: the recording's own camera, then the run
        and the baseline agree). ``ReprocessRequestError`` naming the field for a bad
        camera; nothing is stored then. Returns the job's status."""
        try:
            text = check_camera(camera, recording) if camera is not None else None
        except RecordingError as exc:
            raise ReprocessRequestError(
                "campaign_id", f"its recording cannot be read: {exc}"
            ) from exc
        with self._lock:
            jid = max(self._ids(), default=0) + 1
            d = self._dir(jid)
            d.mkdir(parents=True)
            if text is not None:
                (d / "camera.json").write_text(text)
            job = {
                "id": jid,
                "campaign_id": campaign_id,
                "recording": str(recording),
                "camera": "given" if text is not None else "recording",
                "tracking": tracking,
                "filter": filter_state,
                "status": "queued",
                "created": _now(),
                "started": None,
                "finished": None,
                "error": None,
                "frames": None,
                "summary": None,
            }
            _write_json(d / "job.json", job)
        self._enqueue(jid)
        return self.status(jid)

    def cancel(self, jid: int) -> dict:
        """Cancel a queued or running job (its partial output is removed)."""
        job = self.status(jid)
        if job["status"] in ("queued", "running"):
            with self._lock:
                if not self.jobs.cancel(self._key(jid)):
                    self._finish(jid, "cancelled", None)
        return self.status(jid)

    # -- queries ----------------------------------------------------------------------
    def status(self, jid: int) -> dict:
        job = self._read(jid)
        if job is None:
            raise UnknownReprocessingError(f"no re-processing with id {jid}")
        job["files"] = [n for n in FILES if self.file_path(jid, n, check=False) is not None]
        running = job["status"] == "running"
        job["dashboard_url"] = self.dashboard_url(jid) if running else None
        done, planned = self._progress.get(jid, (None, None)) if running else (None, None)
        job["frames_done"], job["frames_planned"] = done, planned
        job.setdefault("warnings", [])
        return job

    def list(self, campaign_id: int | None = None) -> list[dict]:
        """Every job (of ``campaign_id`` when given), newest first."""
        out = []
        for jid in sorted(self._ids(), reverse=True):
            try:
                job = self.status(jid)
            except UnknownReprocessingError:
                continue
            if campaign_id is None or job["campaign_id"] == campaign_id:
                out.append(job)
        return out

    def file_path(self, jid: int, name: str, check: bool = True) -> Path | None:
        """The job's file ``name`` (``FILES``), None before it exists."""
        if check:
            self.status(jid)
        where, _ = FILES[name]
        d = self._dir(jid)
        stem = f"{Path(self._job(jid)['recording']).stem}.csv"
        p = d / where / stem if where in ("run", "baseline") else d / where
        return p if p.exists() else None

    # -- the runner -------------------------------------------------------------------
    def _run_one(self, jid: int, should_stop: Callable[[], bool]) -> None:
        """The job: run, baseline, compare (module docstring)."""
        d = self._dir(jid)
        job = self._read(jid)
        if job is None:
            return
        job.update(status="running", started=_now(), error=None)
        _write_json(d / "job.json", job)
        camera_path = str(d / "camera.json") if job["camera"] == "given" else None
        try:
            for sub in ("run", "baseline"):
                shutil.rmtree(d / sub, ignore_errors=True)
            with open_cluster(**self._cluster()) as session:
                self._on_cluster(jid, session)
                job["warnings"] = list(session.warnings)
                _write_json(d / "job.json", job)
                common = dict(
                    filter_state=job["filter"],
                    progress=False,
                    should_stop=should_stop,
                    session=session,
                )
                run = reprocess(
                    [job["recording"]],
                    d / "run",
                    **common,
                    settings=Settings(camera_path=camera_path, tracking=job["tracking"]),
                    on_progress=partial(self._on_progress, jid, 0),
                )
                # the baseline measured as the run was (the camera JSON may have turned the
                # pixel fit and the range bias's learning off), so that the two differ
                # by the camera only
                measured = run["recordings"][0]
                reprocess(
                    [job["recording"]],
                    d / "baseline",
                    **common,
                    settings=Settings(
                        tracking=job["tracking"],
                        pixel_fit=measured["pixel_fit"],
                        learn_range_bias=measured["range_bias"] is not None,
                    ),
                    on_progress=partial(self._on_progress, jid, 1),
                )
            # matplotlib with it: imported by the first comparison, not with the server
            from tofpose.batch.compare import compare_runs

            summary = compare_runs(str(d / "baseline"), str(d / "run"), d)
        except ReprocessCancelledError:
            if self.jobs.is_cancelled(self._key(jid)):
                self._finish(jid, "cancelled", None)
            else:  # the server stops: run it again at its next start
                job.update(status="queued", started=None)
                _write_json(d / "job.json", job)
            return
        except SystemExit as exc:  # tofpose.io.camera_file.pipeline_for's message for the user
            self._finish(jid, "failed", str(exc.code).removeprefix("tofpose: "))
            return
        except Exception as exc:  # noqa: BLE001 (the job says failed, with the error)
            log.exception("re-processing %d failed", jid)
            self._finish(jid, "failed", f"{type(exc).__name__}: {exc}")
            return
        finally:
            self._on_cluster(jid, None)
            self._progress.pop(jid, None)
        rec = summary["recordings"][Path(job["recording"]).stem]
        job = self._job(jid)
        job.update(
            status="complete", finished=_now(), frames=run["recordings"][0]["frames"], summary=rec
        )
        _write_json(d / "job.json", job)

    def _on_progress(self, jid: int, run: int, frames_done: int, frames: int) -> None:
        """Pass ``run`` (0: the new calibration, 1: the baseline) of job ``jid`` has
        ``frames_done`` of its ``frames`` output."""
        self._progress[jid] = (run * frames + frames_done, 2 * frames)

    def _finish(self, jid: int, status: str, error: str | None) -> None:
        job = self._job(jid)
        job.update(status=status, finished=_now(), error=error)
        if status == "cancelled":
            for sub in ("run", "baseline"):
                shutil.rmtree(self._dir(jid) / sub, ignore_errors=True)
        _write_json(self._dir(jid) / "job.json", job)

    def _read(self, jid: int) -> dict | None:
        try:
            return json.loads((self._dir(jid) / "job.json").read_text())
        except (OSError, ValueError):
            return None

    def _job(self, jid: int) -> dict:
        """Job ``jid``'s ``job.json``; ``UnknownReprocessingError`` when it cannot be read."""
        job = self._read(jid)
        if job is None:
            raise UnknownReprocessingError(f"no re-processing with id {jid}")
        return job
