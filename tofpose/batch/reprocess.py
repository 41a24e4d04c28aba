"""Re-process recordings on Dask in chunks of frames, to the same CSV ``tofpose
estimate`` writes, byte for byte (``tofpose reprocess``).

The pipeline carries state from frame to frame (the persistence history of the last K
frames, the tracker's last pose and its re-acquisition count), so a chunk cannot simply
start at its first frame. Each chunk starts earlier, at its *origin*, and runs a warm-up
over frames the previous chunk outputs. It is exact once its state has caught up with
the serial run's, and that is checked, not assumed: both the chunk (over its warm-up)
and the previous chunk (over the same frames, at its end) record
``PosePipeline.state_digest()`` after each frame. Equal digests at some warm-up frame
mean equal state there, hence equal results from there on (the pipeline is
deterministic). A chunk whose digests never meet the previous one's (e.g. a tracker
that never lost its target, its re-acquisition count out of phase) is run again from
the previous chunk's own origin, which reproduces that chunk's verified run and carries
on through this one. The manifest (``reprocess.json``) says, per chunk boundary, which
of the two happened.

Warm-up: 2 (K - 1) frames in acquisition mode; in tracking mode the origin is a
multiple of the re-acquisition period N at least K - 1 + N frames back (the serial
run re-acquires at multiples of N while it keeps its target).

The relative-state filter (``--filter``) remembers every frame, so it is not chunked:
the workers store each frame's raw pose (``chunks/*.npz``) and the filter (by default
the smoother of ``tofpose.lab.smoothing``) runs once over them in order, on the client
(about 1.6 ms a frame smoothed, 0.6 ms causal).
"""

from __future__ import annotations

import csv
import io
import os
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tofpose.batch.cluster import ClusterSession, session_or_open
from tofpose.batch.progress import RunProgress
from tofpose.batch.worker import ProgressReporter
from tofpose.io.pose_csv import CSV_COLUMNS, FILTER_COLUMNS, HeldRows, pose_row
from tofpose.io.recording import open_recording
from tofpose.stages.pose.range_bias import LearnedRangeBias

DEFAULT_CHUNK_FRAMES = 512
POLL_S = 0.1


class ReprocessError(ValueError):
    """Recordings or settings that cannot be re-processed; the message says which."""


class ReprocessCancelledError(RuntimeError):
    """``should_stop`` turned true: the run was cancelled before its CSVs were written."""


@dataclass(frozen=True)
class Settings:
    """What every chunk's pipeline is built from (``tofpose.io.camera_file.pipeline_for``)."""

    camera_path: str | None = None
    catalog_path: str | None = None
    tracking: bool = False
    moving: bool = False  # each pose from its own frame (as ``estimate --filter``)
    # each recording's range bias learned first, as ``estimate`` does
    # (``io.camera_file.learned_range_bias``; its chunks carry it; None: with the pixel
    # fit)
    learn_range_bias: bool | None = None
    # each pose refined on its pixels (None: as ``estimate``'s default, on unless the
    # camera JSON carries a covariance scale: ``io.camera_file.resolve_pixel_fit``)
    pixel_fit: bool | None = None


@dataclass(frozen=True)
class Chunk:
    """Frames [start, stop) of recording ``path`` output, after a warm-up from ``origin``;
    digests are recorded for the warm-up and for the last ``tail`` frames (the next
    chunk's warm-up); ``range_bias``: the range offset's prior learned over the
    recording (None: the configured one); ``pixel_fit``: each pose refined on its pixels
    (``Settings.pixel_fit`` resolved for the recording's camera)."""

    path: str
    index: int
    origin: int
    start: int
    stop: int
    tail: int
    range_bias: LearnedRangeBias | None = None
    pixel_fit: bool = True

    @property
    def name(self) -> str:
        return f"{Path(self.path).stem}-{self.start:08d}"


def warmup_origin(start: int, k_frames: int, tracking: bool, reacquire_every: int) -> int:
    """The origin of a chunk that outputs from ``start`` (module docstring)."""
    if start == 0:
        return 0
    if not tracking:
        return max(0, start - 2 * (k_frames - 1))
    n = reacquire_every
    return max(0, (start - (k_frames - 1) - n) // n * n)


def plan(
    path: str, n_frames: int, chunk_frames: int, k_frames: int, tracking: bool, reacquire_every: int
) -> list[Chunk]:
    """The chunks of one recording of ``n_frames``."""
    starts = list(range(0, n_frames, chunk_frames))
    origins = [warmup_origin(s, k_frames, tracking, reacquire_every) for s in starts]
    out = []
    for j, s in enumerate(starts):
        stop = min(s + chunk_frames, n_frames)
        tail = starts[j + 1] - origins[j + 1] if j + 1 < len(starts) else 0
        out.append(Chunk(path, j, origins[j], s, stop, tail))
    return out


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def run_chunk(
    chunk: Chunk,
    settings: Settings,
    out_dir: str,
    progress_topic: str | None = None,
    read_ahead: bool | None = None,
) -> dict:
    """The task: run frames [origin, stop), write the rows of [start, stop) as
    ``chunks/<name>.csv`` (no header) and their raw poses as ``chunks/<name>.npz``
    (atomically); returns {"name", "warm": digests of frames [origin, start), "tail":
    digests of the last ``tail`` frames (those it ran), "tail_first": the frame of the
    first of them, "ok", "seconds", "cpu_s" (its thread's CPU time)} (digests as hex
    strings).
    ``progress_topic``: the run's event topic, on which the frames output so far are
    reported while it runs (``tofpose.batch.worker.ProgressReporter``).
    ``read_ahead``: read the next block in a thread (``Recording.blocks``; None: when
    this process may use more than one core); the client passes
    ``ClusterSession.read_ahead``, false where workers share the cores."""
    from tofpose.core.threads import single_threaded_blas
    from tofpose.io.camera_file import pipeline_for

    single_threaded_blas()
    t0, cpu0 = time.perf_counter(), time.thread_time()
    rows = io.StringIO()
    wr = csv.writer(rows)
    n = chunk.stop - chunk.start
    ok = np.zeros(n, bool)
    R = np.full((n, 3, 3), np.nan)
    t_mm = np.full((n, 3), np.nan)
    cov = np.full((n, 6, 6), np.nan)
    times = np.zeros(n)
    warm, tail = [], []
    # the next chunk's warm-up may reach back past this chunk's start (a chunk shorter
    # than a warm-up): its digests then include warm-up frames of this one
    tail_first = max(chunk.origin, chunk.stop - chunk.tail)
    report = ProgressReporter(progress_topic, chunk.name)
    with open_recording(chunk.path) as rec:
        pipe = pipeline_for(
            rec,
            chunk.path,
            settings.catalog_path,
            settings.camera_path,
            settings.tracking,
            moving=settings.moving,
            pixel_fit=chunk.pixel_fit,
            range_bias=chunk.range_bias,
        )
        for first, (grays, dists, ts) in rec.blocks(
            chunk.origin, chunk.stop, read_ahead=read_ahead
        ):
            for k, tk in enumerate(ts.tolist()):
                i = first + k
                r = pipe.process(grays[k], dists[k], tk)
                if i < chunk.start or i >= tail_first:
                    digest = pipe.state_digest().hex()
                    if i >= tail_first:
                        tail.append(digest)
                    if i < chunk.start:
                        warm.append(digest)
                        continue
                j = i - chunk.start
                wr.writerow(pose_row(i, tk, r))
                times[j] = tk
                if r.ok:
                    ok[j], R[j], t_mm[j], cov[j] = True, r.R, r.t_mm, r.covariance
                report(j + 1)
    chunks = Path(out_dir) / "chunks"
    chunks.mkdir(parents=True, exist_ok=True)
    _write_atomic(chunks / f"{chunk.name}.csv", rows.getvalue().encode())
    buf = io.BytesIO()
    np.savez(buf, ok=ok, R=R, t_mm=t_mm, covariance=cov, time_s=times)
    _write_atomic(chunks / f"{chunk.name}.npz", buf.getvalue())
    return {
        "name": chunk.name,
        "warm": warm,
        "tail": tail,
        "tail_first": tail_first,
        "ok": int(ok.sum()),
        "seconds": time.perf_counter() - t0,
        "cpu_s": time.thread_time() - cpu0,
    }


def synced_frame(previous: Chunk, prev_result: dict, chunk: Chunk, result: dict) -> int | None:
    """The first warm-up frame of ``chunk`` at which its state equals the previous
    chunk's (equal digests), or None."""
    first_tail = prev_result.get("tail_first", previous.stop - previous.tail)
    for k, digest in enumerate(result["warm"]):
        frame = chunk.origin + k
        m = frame - first_tail
        if 0 <= m < len(prev_result["tail"]) and prev_result["tail"][m] == digest:
            return frame
    return None


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def reprocess(
    recordings: list[str],
    out_dir: str | Path,
    *,
    settings: Settings | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    filter_state: bool = False,
    causal_filter: bool = False,
    chunk_frames: int = DEFAULT_CHUNK_FRAMES,
    progress: bool = True,
    should_stop=None,
    niceness: int = 0,
    session: ClusterSession | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Re-process ``recordings`` into ``out_dir``: ``<stem>.csv`` per recording (what
    ``tofpose estimate`` writes for it), ``chunks/``, and ``reprocess.json`` (returned):
    settings, per recording its frames, poses and chunk boundaries, and the run's
    throughput. ``ReprocessError`` for recordings that cannot be read or named apart.
    ``should_stop() -> bool``, polled every ``POLL_S``: when it turns true the chunks
    still queued are cancelled and ``ReprocessCancelledError`` raised (no CSV is
    written). ``niceness``: the LocalCluster workers' priority is lowered by it (a
    server's live loop keeps its core). ``session``: an open cluster to run on (the
    server runs two passes of a job on one); else one is opened from ``workers`` /
    ``scheduler`` (``tofpose.batch.cluster.open_cluster``) and closed at the end.
    ``on_progress(frames_done, frames)``: called as running chunks report their frames
    (``tofpose.batch.progress``), not only at a chunk's end. ``filter_state``,
    ``causal_filter``: as ``tofpose estimate``'s (the filter runs once over every
    chunk's poses, on the client)."""
    from dask.distributed import TimeoutError as DaskTimeout
    from dask.distributed import wait

    from tofpose.io.camera_file import learned_range_bias, pipeline_for, resolve_pixel_fit

    settings = settings or Settings()
    if filter_state:  # poses the filter follows: from single frames, as estimate --filter
        settings = replace(settings, moving=True)
    if chunk_frames < 1:
        raise ReprocessError(f"--chunk-frames must be >= 1 (got {chunk_frames})")
    stems = [Path(p).stem for p in recordings]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise ReprocessError(f"two recordings are named {dup[0]!r}: their CSVs would collide")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    chunks: dict[str, list[Chunk]] = {}
    method: dict[str, dict[str, Any]] = {}
    learn_s = 0.0  # the range bias's learning, on the client before the cluster's work
    for path in recordings:
        with open_recording(path) as rec:  # RecordingError names what is wrong
            pipe = pipeline_for(
                rec,
                path,
                settings.catalog_path,
                settings.camera_path,
                settings.tracking,
                moving=settings.moving,
            )
            cfg = pipe.config
            if should_stop is not None and should_stop():
                raise ReprocessCancelledError("re-processing cancelled")
            pixel_fit = resolve_pixel_fit(settings.pixel_fit, settings.camera_path)
            learn_t0 = time.perf_counter()
            learned = (
                learned_range_bias(
                    rec,
                    path,
                    settings.catalog_path,
                    settings.camera_path,
                    pixel_fit=pixel_fit,
                    progress=False,
                    should_stop=should_stop,
                )
                if (pixel_fit if settings.learn_range_bias is None else settings.learn_range_bias)
                else None
            )
            if should_stop is not None and should_stop():  # during the learning
                raise ReprocessCancelledError("re-processing cancelled")
            learn_s += time.perf_counter() - learn_t0
            summary_line = (
                ""
                if learned is None
                else learned.summary(cfg.range_bias_sigma_mm, cfg.calibrated_range_bias_sigma_mm)
            )
            method[path] = {
                "pixel_fit": pixel_fit,
                "range_bias": None if learned is None else asdict(learned),
                # the prior each frame was measured with (the learned sigma capped at the
                # configured ones: ``LearnedRangeBias.prior_sigma_mm``)
                "range_bias_sigma_mm": None
                if learned is None
                else learned.prior_sigma_mm(cfg.range_bias_sigma_mm),
                "calibrated_range_bias_sigma_mm": None
                if learned is None
                else learned.prior_sigma_mm(cfg.calibrated_range_bias_sigma_mm),
                "range_bias_summary": summary_line,
            }
            if learned is not None and progress:
                print(f"{Path(path).name}: {summary_line}", file=sys.stderr)
            chunks[path] = [
                replace(c, range_bias=learned, pixel_fit=pixel_fit)
                for c in plan(
                    str(path),
                    rec.n_frames,
                    chunk_frames,
                    cfg.persistence.k_frames,
                    settings.tracking,
                    cfg.tracking.reacquire_every,
                )
            ]
    total = sum(c.stop - c.start for cs in chunks.values() for c in cs)
    t0 = time.perf_counter()
    first_progress_s: float | None = None
    results: dict[Chunk, dict] = {}
    boundaries: dict[str, list[dict]] = {p: [] for p in recordings}
    bar = tqdm(total=total, unit="frame", desc="reprocess", disable=not progress, file=sys.stderr)
    with session_or_open(session, workers, scheduler, niceness) as cluster:
        client = cluster.client
        t_connected = time.perf_counter()
        with RunProgress(client) as live:
            # a chunk's task is named by the run and the chunk (Dask's task stream and
            # dashboard show which chunk ran where, and how often)
            run_id = uuid.uuid4().hex[:12]
            futures = {
                client.submit(
                    run_chunk,
                    c,
                    settings,
                    str(out),
                    live.topic,
                    cluster.read_ahead,
                    key=f"tofpose-reprocess-{run_id}-{c.name}",
                ): c
                for cs in chunks.values()
                for c in cs
            }
            pending = set(futures)
            stored = shown = 0
            cpu_s = 0.0
            while pending:
                try:
                    finished, pending = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED")
                except DaskTimeout:
                    finished = set()
                for fut in finished:
                    c = futures[fut]
                    results[c] = fut.result()  # a task's exception surfaces here
                    cpu_s += results[c]["cpu_s"]
                    live.finished(c.name)
                    stored += c.stop - c.start
                done = stored + live.running_frames()
                if done != shown:
                    if first_progress_s is None:
                        first_progress_s = time.perf_counter() - t0
                    bar.update(done - shown)
                    shown = done
                    if on_progress is not None:
                        on_progress(done, total)
                if should_stop is not None and should_stop():
                    client.cancel(list(pending))
                    bar.close()
                    raise ReprocessCancelledError("re-processing cancelled")
        reruns = 0
        for path, cs in chunks.items():
            for j in range(1, len(cs)):
                prev, cur = cs[j - 1], cs[j]
                k = synced_frame(prev, results[prev], cur, results[cur])
                if k is not None:
                    boundaries[path].append({"chunk": j, "start": cur.start, "synced_at_frame": k})
                    continue
                # run again from the previous chunk's origin: its verified run, carried on
                again = replace(cur, origin=prev.origin)
                results[cur] = client.submit(
                    run_chunk,
                    again,
                    settings,
                    str(out),
                    None,
                    cluster.read_ahead,
                    key=f"tofpose-reprocess-{run_id}-{cur.name}-again",
                ).result()
                cs[j] = again
                results[again] = results[cur]
                cpu_s += results[cur]["cpu_s"]
                reruns += 1
                boundaries[path].append(
                    {"chunk": j, "start": cur.start, "continued_from_frame": prev.origin}
                )
    bar.close()
    wall_s = time.perf_counter() - t0
    work_s = time.perf_counter() - t_connected
    summary_recordings: list[dict[str, Any]] = []
    summary: dict[str, Any] = {
        "format": "tofpose-reprocess",
        "finished": _now(),
        "settings": asdict(settings),
        "filter": filter_state,
        # with the filter: its state from the poses up to each frame, not from all
        "causal_filter": causal_filter,
        "chunk_frames": chunk_frames,
        "recordings": summary_recordings,
    }
    for path, cs in chunks.items():
        csv_path = out / f"{Path(path).stem}.csv"
        n_ok = _concatenate(
            cs, out, csv_path, filter_state=filter_state, causal_filter=causal_filter
        )
        summary_recordings.append(
            {
                "path": str(path),
                "csv": csv_path.name,
                "frames": cs[-1].stop if cs else 0,
                "ok": n_ok,
                "chunks": len(cs),
                "boundaries": boundaries[path],
                # how its frames were measured (``Settings.pixel_fit`` resolved; the
                # range bias learned over it, None: the configured prior)
                **method[path],
            }
        )
    n_workers = cluster.workers
    summary["run"] = {
        "workers": n_workers,
        "cluster": scheduler or f"LocalCluster({n_workers})",
        "warnings": list(cluster.warnings),
        # whether each chunk read its next block in a thread of its own
        "read_ahead": cluster.read_ahead,
        "frames": total,
        "wall_s": wall_s,
        # 0 on a cluster the caller opened
        "cluster_start_s": wall_s - work_s,
        # from the call to the first frame output (reported by a running chunk)
        "first_progress_s": first_progress_s,
        # from the cluster's start to the last chunk's CSV
        "frames_per_s": total / work_s if work_s > 0 else None,
        # once warm: frames output over the chunks' own time, times the workers
        "frames_per_s_warm": total * n_workers / sum(r["seconds"] for r in results.values()),
        "chunks_run_again": reruns,
        # learning the recordings' range biases first, on the client (not in wall_s)
        "range_bias_s": learn_s,
        # the chunks' threads' CPU time, re-runs included
        "cpu_s": cpu_s,
    }
    import json

    (out / "reprocess.json").write_text(json.dumps(summary, indent=2))
    return summary


def _concatenate(
    cs: list[Chunk], out: Path, csv_path: Path, *, filter_state: bool, causal_filter: bool = False
) -> int:
    """Write one recording's CSV from its chunks, in order; returns its poses. With
    ``filter_state`` the filter's columns over all of them (``pose_csv.HeldRows``, as
    estimate --filter)."""
    n_ok = 0
    tmp = csv_path.with_name(f".{csv_path.name}.tmp")
    held = HeldRows()
    with open(tmp, "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(CSV_COLUMNS + (FILTER_COLUMNS if filter_state else ()))
        for c in cs:
            text = (out / "chunks" / f"{c.name}.csv").read_bytes().decode()  # keeps \r\n
            raw = np.load(out / "chunks" / f"{c.name}.npz")
            n_ok += int(raw["ok"].sum())
            if not filter_state:
                fh.write(text)
                continue
            for k, row in enumerate(csv.reader(io.StringIO(text))):
                pose = (raw["R"][k], raw["t_mm"][k], raw["covariance"][k])
                held.add(row, float(raw["time_s"][k]), pose if raw["ok"][k] else None)
        if filter_state:
            held.write(wr, causal=causal_filter)
    os.replace(tmp, csv_path)
    return n_ok
