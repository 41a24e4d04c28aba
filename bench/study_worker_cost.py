"""Where a study's 1-worker run loses against a serial run (issue 47, item 4), in CPU
seconds, which other processes on a shared machine disturb much less than wall time.

Per repeat, ``bench/goals.py``'s study (``bench.scaleout.study_spec``) serially in this
process and on a LocalCluster of 1 worker (chunks of 8 frames as the goals run, and of
48): frames/s of both, this process's CPU per frame of the serial loop, the worker
process's whole CPU per frame over the run (its task thread, event loop and Dask's
threads) and the task's frame loop's thread CPU per frame (``run["cpu_s"]``). Then, in
one worker, the same study chunks with Dask's statistical profiler stopped and running
(``distributed.worker.profile``, on by default: it samples the running task's stack 100
times a second), each chunk once in each mode, which mode goes first alternating: the
frame loop's thread CPU and the worker process's CPU per frame.

Run: ``python bench/study_worker_cost.py [--repeats 3]`` (prints JSON lines, then a
summary).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._common import all_cores  # noqa: E402
from bench.scaleout import serial_study, study_spec  # noqa: E402

PROFILER_CHUNKS = 24


def _process_cpu_s() -> float:
    t = os.times()
    return t.user + t.system


def one_worker_run(chunk_frames: int) -> dict:
    """The goals' study on a new 1-worker LocalCluster in chunks of ``chunk_frames``:
    frames/s, the worker process's CPU per frame, its frame loops' CPU per frame (ms)."""
    from tofpose.batch.cluster import open_cluster
    from tofpose.study.run import run_study
    from tofpose.study.store import read_manifest

    spec = dataclasses.replace(study_spec(48), chunk_frames=chunk_frames)
    with tempfile.TemporaryDirectory() as d, open_cluster(1) as session:
        (before,) = session.client.run(_process_cpu_s).values()
        run_study(spec, Path(d) / "s", session=session, progress=False, report=False)
        (after,) = session.client.run(_process_cpu_s).values()
        run = read_manifest(Path(d) / "s")["run"]
    return {
        "fps": run["frames_per_s"],
        "process_cpu_ms": 1e3 * (after - before) / spec.n_frames,
        "loop_cpu_ms": 1e3 * run["cpu_s"] / run["frames_run"],
    }


def _chunk_cpu_ms(spec_doc: dict, cell: int, start: int) -> tuple[float, float]:
    """In a worker: one 8-frame study chunk, per frame (ms) its frame loop's thread CPU and
    the worker process's CPU (every thread) while it ran."""
    from tofpose.study.frames import run_chunk

    with tempfile.TemporaryDirectory() as d:
        c0 = time.process_time()
        r = run_chunk(spec_doc, cell, start, start + 8, d)
        process_s = time.process_time() - c0
    return 1e3 * r["cpu_s"] / r["frames"], 1e3 * process_s / r["frames"]


def _set_profiler(running: bool, dask_worker) -> None:
    for name in ("profile", "profile-cycle"):
        callback = dask_worker.periodic_callbacks.get(name)
        if callback is not None:
            callback.start() if running else callback.stop()


def profiler_cost() -> dict:
    """Per frame (ms, medians), the frame loop's and the worker process's CPU of the same
    chunks in one worker with Dask's profiler stopped and running, each chunk run once in
    each mode: {mode: (loop, process)}."""
    import dask
    import distributed  # noqa: F401 (its defaults loaded before the setting below)

    from tofpose.batch.cluster import open_cluster

    doc = study_spec(48).to_dict()
    got: dict[str, list[tuple[float, float]]] = {"stopped": [], "running": []}
    profiling = dask.config.set({"distributed.worker.profile.enabled": True})
    with profiling, open_cluster(1) as session:
        c = session.client
        c.submit(_chunk_cpu_ms, doc, 0, 0, pure=False).result()  # the pipeline
        for k in range(PROFILER_CHUNKS):
            # the chunk's second run is the cheaper one (warm caches): each mode goes
            # first every other time
            for mode in sorted(got, reverse=k % 2 == 1):
                c.run(_set_profiler, mode == "running")
                args = (doc, k % 4, 8 * (k // 4) % 48)
                got[mode].append(c.submit(_chunk_cpu_ms, *args, pure=False).result())
    return {mode: tuple(np.median(np.array(v), axis=0).tolist()) for mode, v in got.items()}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    all_cores()
    spec = study_spec(48)
    rows = []
    for _ in range(args.repeats):
        serial_fps, serial_cpu_s = serial_study(spec)
        row = {"serial_fps": serial_fps, "serial_cpu_ms": 1e3 * serial_cpu_s}
        for chunk in (8, 48):
            row[f"chunks of {chunk}"] = one_worker_run(chunk)
        rows.append(row)
        print(json.dumps(row), flush=True)
    # the first repeat's serial loop builds the study's pipeline: left out
    kept = rows[1:] or rows
    for chunk in (8, 48):
        runs = [r[f"chunks of {chunk}"] for r in kept]
        fps = np.median([w["fps"] / r["serial_fps"] for w, r in zip(runs, kept, strict=True)])
        cpu = np.median(
            [r["serial_cpu_ms"] / w["process_cpu_ms"] for w, r in zip(runs, kept, strict=True)]
        )
        print(
            f"chunks of {chunk}: frames/s of 1 worker / serial {fps:.3f}; serial CPU per "
            f"frame / the worker process's {cpu:.3f}; ms per frame: serial loop "
            f"{np.median([r['serial_cpu_ms'] for r in kept]):.2f}, worker process "
            f"{np.median([w['process_cpu_ms'] for w in runs]):.2f}, its frame loops "
            f"{np.median([w['loop_cpu_ms'] for w in runs]):.2f} (medians of {len(kept)})"
        )
    p = profiler_cost()
    print(
        f"Dask's profiler, same chunks in one worker ({PROFILER_CHUNKS} each, alternating), "
        f"CPU ms per frame: running: frame loop {p['running'][0]:.2f}, worker process "
        f"{p['running'][1]:.2f}; stopped: frame loop {p['stopped'][0]:.2f}, worker process "
        f"{p['stopped'][1]:.2f}"
    )


if __name__ == "__main__":
    main()
