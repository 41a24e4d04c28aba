"""Run a study on a Dask cluster: submit its chunks, follow them, summarise, report.

Chunks already in the store (a run of the same spec that was interrupted) are not run
again. Progress goes to ``study.json`` (``chunks_done``, ``frames_done``, ``eta_s``),
which is what the server's ``GET /api/studies/{id}`` reads, and to a progress bar, as
the frames are measured: a running chunk reports its frames every half second
(``tofpose.batch.progress``), so progress moves within a chunk, not only at its end.
``frames_done`` counts the frames stored and those measured by running chunks; when the
run stops it is the frames stored. Ctrl-C (or ``should_stop`` returning True) cancels
the outstanding tasks and leaves the store marked ``incomplete`` with the chunks that
were finished; a task that raises marks it ``failed`` with the error.
"""

from __future__ import annotations

import hashlib
import sys
import time
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

from tqdm import tqdm

from tofpose.batch.cluster import ClusterSession, session_or_open
from tofpose.batch.progress import RunProgress
from tofpose.study.frames import run_chunk
from tofpose.study.spec import StudySpec
from tofpose.study.store import (
    chunk_name,
    open_store,
    present_chunks,
    read_frames,
    remove_temporary,
    write_manifest,
)
from tofpose.study.summary import summarise

POLL_S = 0.1


class StudyCancelledError(RuntimeError):
    """The study was stopped before every chunk ran; the store says ``incomplete``."""


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def run_study(
    spec: StudySpec,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    should_stop: Callable[[], bool] | None = None,
    report: bool = True,
    niceness: int = 0,
    on_cluster: Callable[[ClusterSession | None], None] | None = None,
    session: ClusterSession | None = None,
) -> dict:
    """Run ``spec`` into ``out_dir`` (``tofpose.study.store``); returns the summary
    (``summary.json``). ``workers`` / ``scheduler``: ``batch.cluster.open_cluster``.
    ``report``: also write report.html and report.pdf (``tofpose.study.report``);
    ``niceness``: lower a LocalCluster's workers' priority (``open_cluster``);
    ``on_cluster``: called with the cluster once it is up and with None when it is
    closed (the server shows its dashboard meanwhile); ``session``: an open cluster to
    run on (left open) instead of one opened for the study."""
    from dask.distributed import TimeoutError as DaskTimeout
    from dask.distributed import wait

    root = Path(out_dir).resolve()
    manifest = open_store(root, spec)
    remove_temporary(root)
    done = present_chunks(root)
    chunks = spec.chunks()
    todo = [c for c in chunks if c not in done]
    frames_stored = sum(b - a for _, a, b in done & set(chunks))
    stored_at_start = frames_stored
    token = hashlib.sha1(spec.to_json().encode()).hexdigest()[:12]
    manifest.update(
        status="running",
        started=_now(),
        error=None,
        cluster=scheduler or f"LocalCluster({workers or 'auto'})",
        chunks_done=len(chunks) - len(todo),
        frames_done=frames_stored,
        eta_s=None,
    )
    write_manifest(root, manifest)
    results: list[dict] = []
    t0 = time.perf_counter()
    t_connected = t0
    first_progress_s: float | None = None
    bar = tqdm(
        total=spec.n_frames,
        initial=frames_stored,
        unit="frame",
        desc=f"study {spec.name}",
        disable=not progress,
        file=sys.stderr,
    )
    try:
        with session_or_open(session, workers, scheduler, niceness) as cluster:
            client = cluster.client
            manifest["workers"] = cluster.workers
            manifest["warnings"] = list(cluster.warnings)
            write_manifest(root, manifest)
            t_connected = time.perf_counter()
            if on_cluster is not None:
                on_cluster(cluster)
            doc = spec.to_dict()
            with RunProgress(client) as live:
                names = {}
                for c, a, b in todo:
                    fut = client.submit(
                        run_chunk,
                        doc,
                        c,
                        a,
                        b,
                        str(root),
                        live.topic,
                        pure=False,
                        key=f"tofpose-study-{token}-{c}-{a}",
                    )
                    names[fut] = chunk_name(c, a, b)
                pending = set(names)
                shown = frames_stored
                while pending:
                    try:
                        finished, pending = wait(
                            pending, timeout=POLL_S, return_when="FIRST_COMPLETED"
                        )
                    except DaskTimeout:
                        finished = set()
                    for fut in finished:
                        res = fut.result()  # a task's exception surfaces here
                        live.finished(names[fut])
                        results.append(res)
                        manifest["chunks_done"] += 1
                        frames_stored += res["frames"]
                    measured = frames_stored + live.running_frames()
                    if measured != shown:
                        if first_progress_s is None:
                            first_progress_s = time.perf_counter() - t0
                        bar.update(measured - shown)
                        shown = measured
                        manifest["frames_done"] = measured
                        rate = (measured - stored_at_start) / (time.perf_counter() - t_connected)
                        left = spec.n_frames - measured
                        manifest["eta_s"] = left / rate if rate > 0 else None
                        write_manifest(root, manifest)
                    if should_stop is not None and should_stop():
                        client.cancel(list(pending))
                        raise StudyCancelledError(f"study {spec.name!r} stopped")
    except (KeyboardInterrupt, StudyCancelledError):
        manifest.update(status="incomplete", finished=_now(), eta_s=None, frames_done=frames_stored)
        write_manifest(root, manifest)
        raise
    except Exception as exc:
        manifest.update(
            status="failed",
            finished=_now(),
            error=f"{type(exc).__name__}: {exc}",
            frames_done=frames_stored,
        )
        write_manifest(root, manifest)
        raise
    finally:
        bar.close()
        if on_cluster is not None:
            on_cluster(None)
    # every chunk is written: what is left half-written is a killed worker's (its task ran
    # again elsewhere under another temporary name)
    remove_temporary(root)
    wall_s = time.perf_counter() - t0
    measure_s = time.perf_counter() - t_connected
    summary = summarise(spec, read_frames(root, spec))
    loads: dict[int, dict] = {}  # per worker process, its latest (cumulative) counts

    def kernels(load: dict) -> int:
        return load["cache_hits"] + load["cache_misses"]

    for r in results:
        load = r["kernel_load"]
        if load["pid"] not in loads or kernels(load) >= kernels(loads[load["pid"]]):
            loads[load["pid"]] = load
    # how this run went (study.json; summary.json holds only what the frames say, so
    # that the same spec gives the same file on any cluster)
    manifest["run"] = {
        "workers": manifest.get("workers"),
        "cluster": manifest["cluster"],
        "frames_run": sum(r["frames"] for r in results),
        "wall_s": wall_s,
        "cluster_start_s": wall_s - measure_s,
        # from the run's start to the first frame measured (stored or reported running)
        "first_progress_s": first_progress_s,
        # from the cluster's start to the last chunk (the workers' kernel loads included)
        "frames_per_s": sum(r["frames"] for r in results) / measure_s if results else None,
        # the workers' rate once warm: frames over the chunks' own measuring time, times
        # the workers
        "frames_per_s_warm": (
            sum(r["frames"] for r in results)
            * manifest["workers"]
            / sum(r["seconds"] for r in results)
        )
        if results
        else None,
        # the chunks' threads' CPU time (a frame's cost, whatever else the machine runs)
        "cpu_s": sum(r["cpu_s"] for r in results),
        "worker_kernel_load": sorted(loads.values(), key=lambda d: d["pid"]),
    }
    from tofpose.study.report import write_summary

    write_summary(root, summary)
    if report:
        from tofpose.study.report import write_report

        write_report(root, spec, summary, manifest["run"])
    manifest.update(status="complete", finished=_now(), eta_s=0.0)
    write_manifest(root, manifest)
    return summary
