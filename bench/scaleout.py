"""Scale-out on Dask (docs/scaleout.md; docs/results.md, "Scale-out on Dask"): what a
study and a re-processing (acquisition and tracking mode) do per worker on 1 and 2 workers
of this machine against the same work serially in one process, in the same repeat; the
cluster's start-up; the time to the first progress update; chunks run more than once
(counted in Dask's task stream, and the re-processing's own re-runs); whether workers
load the numba kernels from the cache; what a task costs the scheduler and a chunk costs
the store; the live camera loop's frame rate while a study runs in the server; and
``tofpose study --example`` on 2 workers from the command line.

Per-worker efficiency = frames/s on W workers / (W x frames/s of the serial run of the
same repeat), counted from the cluster being up to the last chunk (start-up is reported
apart); its CPU form = the serial run's CPU seconds per frame / a worker's (each chunk's
thread CPU time), which other processes on a shared machine disturb much less. Every
figure is the median over ``--repeats`` repeats, each repeat running serial, 1 worker
and 2 workers one after the other.

Run: ``python bench/scaleout.py [--repeats 3] [--quick] [--recording REC.h5]``
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._common import all_cores, table  # noqa: E402
from tofpose.core.camera import CameraModel  # noqa: E402
from tofpose.study.frames import kernel_load, measure_frame  # noqa: E402
from tofpose.study.spec import StudySpec  # noqa: E402

TOKEN = "bench-token-0123456789"


def study_spec(frames_per_cell: int) -> StudySpec:
    return StudySpec.from_dict(
        {
            "name": "bench",
            "seed": 11,
            "frames_per_cell": frames_per_cell,
            "chunk_frames": 8,
            "grid": {"range_m": [3.0, 6.0], "physics": ["ideal", "lens blur"]},
        }
    )


def serial_study(spec: StudySpec) -> tuple[float, float]:
    """The spec's frames measured in this process, no Dask: (frames/s, CPU s per
    frame)."""
    from tofpose.warmup import warm_up

    warm_up()
    kernel_load()
    cam = CameraModel()
    t0, c0 = time.perf_counter(), time.process_time()
    for c in spec.cells:
        for i in range(spec.frames_per_cell):
            measure_frame(spec, c, i, cam)
    return spec.n_frames / (time.perf_counter() - t0), (time.process_time() - c0) / spec.n_frames


def _executions(stream) -> Counter:
    """How often each tofpose task ran, by key (Dask's task stream)."""
    return Counter(str(t["key"]) for t in stream.data if "tofpose" in str(t["key"]))


def study_run(spec: StudySpec, workers: int) -> dict:
    """One run on a new LocalCluster of ``workers``: frames/s once up, CPU s per frame in
    the workers, cluster start, first progress (from the call), tasks run twice, the
    workers' kernel loads."""
    from dask.distributed import get_task_stream

    from tofpose.batch.cluster import open_cluster
    from tofpose.study.run import run_study
    from tofpose.study.store import read_manifest

    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        with open_cluster(workers) as session, get_task_stream(session.client) as stream:
            start_s = time.perf_counter() - t0
            run_study(spec, Path(d) / "s", session=session, progress=False, report=False)
        run = read_manifest(Path(d) / "s")["run"]
    ran = _executions(stream)
    return {
        "fps": run["frames_per_s"],
        "cpu_per_frame": run["cpu_s"] / run["frames_run"],
        "start_s": start_s,
        "first_progress_s": start_s + run["first_progress_s"],
        "twice": sum(n - 1 for n in ran.values()),
        "loads": run["worker_kernel_load"],
    }


def make_recording(path: Path, n: int) -> None:
    from tofpose.workflows.simulation import simulate

    simulate("range-sweep", n, str(path), 4, None, progress=False)


def serial_estimate(rec: Path, tracking: bool) -> tuple[float, float]:
    """``tofpose estimate --no-pixel-fit`` of ``rec``: (frames/s, CPU s per frame). The
    scale-out's runs measure the centroid pose only (``reprocess_run`` too): their
    subject is the chunking, and the pixel fit's tens of ms a frame would hide its
    costs (a heavier frame makes every per-worker ratio look better)."""
    from tofpose.workflows.measurement import estimate

    with tempfile.TemporaryDirectory() as d:
        t0, c0 = time.perf_counter(), time.process_time()
        s = estimate(
            str(rec),
            str(Path(d) / "e.csv"),
            None,
            None,
            progress=False,
            tracking=tracking,
            pixel_fit=False,
        )
        n = s["frames"]
        return n / (time.perf_counter() - t0), (time.process_time() - c0) / n


def reprocess_run(rec: Path, workers: int, tracking: bool, chunk_frames: int) -> dict:
    """One re-processing on a new LocalCluster of ``workers`` (as ``study_run``)."""
    from dask.distributed import get_task_stream

    from tofpose.batch.cluster import open_cluster
    from tofpose.batch.reprocess import Settings, reprocess

    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        with open_cluster(workers) as session, get_task_stream(session.client) as stream:
            start_s = time.perf_counter() - t0
            s = reprocess(
                [str(rec)],
                d,
                settings=Settings(tracking=tracking, pixel_fit=False),  # as serial_estimate
                chunk_frames=chunk_frames,
                progress=False,
                session=session,
            )
    ran = _executions(stream)
    run = s["run"]
    return {
        "fps": run["frames_per_s"],
        "cpu_per_frame": run["cpu_s"] / run["frames"],
        "start_s": start_s,
        "first_progress_s": start_s + run["first_progress_s"],
        "twice": sum(n - 1 for n in ran.values()) + run["chunks_run_again"],
        "chunks": s["recordings"][0]["chunks"],
        "read_ahead": run["read_ahead"],
    }


def study_example_cli(workers: int) -> dict:
    """``tofpose study --example`` into a new directory on ``workers`` workers, from the
    command line as a user runs it: wall time, and study.json's cluster start and first
    progress."""
    exe = str(Path(sys.executable).with_name("tofpose"))
    with tempfile.TemporaryDirectory() as d:
        spec = Path(d) / "spec.json"
        spec.write_text(
            subprocess.run(
                [exe, "study", "--example"], capture_output=True, text=True, check=True
            ).stdout
        )
        t0 = time.perf_counter()
        subprocess.run(
            [exe, "study", str(spec), "--out", str(Path(d) / "s"), "--workers", str(workers)],
            capture_output=True,
            check=True,
        )
        wall = time.perf_counter() - t0
        run = json.loads((Path(d) / "s" / "study.json").read_text())["run"]
    return {"wall_s": wall, "start_s": run["cluster_start_s"], "first": run["first_progress_s"]}


def scheduler_overhead_ms(n_tasks: int = 2000) -> float:
    """Round trip of a no-op task on a 2-worker LocalCluster, ms per task (batch of n)."""
    from tofpose.batch.cluster import dask_client

    with dask_client(workers=2) as client:
        client.gather(client.map(abs, range(200), pure=False))  # warm the connections
        t0 = time.perf_counter()
        client.gather(client.map(abs, range(n_tasks), pure=False))
        return 1e3 * (time.perf_counter() - t0) / n_tasks


def store_chunk_ms(rows: int = 25, n: int = 40) -> tuple[float, float]:
    """(ms to write one chunk of ``rows`` frames, its size in kB)."""
    import pyarrow as pa

    from tofpose.study.columns import COLUMNS
    from tofpose.study.store import write_chunk

    spec = study_spec(rows)
    cam = CameraModel()
    table_rows = [measure_frame(spec, spec.cells[0], i, cam) for i in range(rows)]
    tab = pa.Table.from_pylist(table_rows, schema=COLUMNS)
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        for k in range(n):
            write_chunk(d, k, 0, rows, tab)
        ms = 1e3 * (time.perf_counter() - t0) / n
        size = (Path(d) / "frames").iterdir().__next__().stat().st_size / 1e3
    return ms, size


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def live_rates(seconds: float) -> dict:
    """The server (simulated camera at its default 10 Hz) measured from outside: frames
    per second of the live loop idle, and while a study runs (and the study's rate)."""
    import httpx

    port = _free_port()
    with tempfile.TemporaryDirectory() as d:
        env = {
            **os.environ,
            "TOFPOSE_DATA_DIR": d,
            "TOFPOSE_PORT": str(port),
            "TOFPOSE_API_TOKEN": TOKEN,
            "TOFPOSE_VISER": "false",
            "TOFPOSE_KERNELS_IN_BACKGROUND": "false",
        }
        cmd = [str(Path(sys.executable).with_name("tofpose")), "serve"]
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        base = f"http://127.0.0.1:{port}"
        auth = {"Authorization": f"Bearer {TOKEN}"}
        try:
            deadline = time.monotonic() + 180
            while time.monotonic() < deadline:
                try:
                    if httpx.get(f"{base}/api/pose/latest").status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                time.sleep(0.5)

            def rate(span: float) -> tuple[float, float]:
                a = httpx.get(f"{base}/api/pose/latest").json()["frame_index"]
                t0 = time.monotonic()
                time.sleep(span)
                b = httpx.get(f"{base}/api/pose/latest").json()["frame_index"]
                return (b - a) / (time.monotonic() - t0), time.monotonic() - t0

            time.sleep(3.0)
            idle, _ = rate(seconds)
            spec = {
                "name": "load",
                "seed": 1,
                "frames_per_cell": 2000,
                "chunk_frames": 8,
                "grid": {"range_m": [3.0, 6.0]},
            }
            sid = httpx.post(f"{base}/api/studies", json=spec, headers=auth).json()["id"]
            while httpx.get(f"{base}/api/studies/{sid}").json()["frames_done"] < 16:
                time.sleep(0.5)  # the workers are up and measuring
            f0 = httpx.get(f"{base}/api/studies/{sid}").json()["frames_done"]
            busy, span = rate(seconds)
            f1 = httpx.get(f"{base}/api/studies/{sid}").json()["frames_done"]
            study = httpx.get(f"{base}/api/studies/{sid}").json()
            httpx.post(f"{base}/api/studies/{sid}/cancel", headers=auth)
            return {
                "idle_hz": idle,
                "busy_hz": busy,
                "study_fps": (f1 - f0) / span,
                "cluster": study["cluster"],
            }
        finally:
            proc.terminate()
            proc.wait(timeout=60)


def _med(values) -> float:
    return float(np.median(values))


def _rows(name: str, serial: list[tuple[float, float]], runs: dict[int, list[dict]]) -> list:
    """Table rows of one kind of work: per worker count, medians over the repeats of the
    rate, the per-worker efficiency against the serial run of the same repeat, its CPU
    form, the cluster start, the first progress, and the tasks that ran twice (summed)."""
    rows = [[name, "serial", f"{_med([f for f, _ in serial]):.1f}", "1", "1", "-", "-", "-"]]
    for w, rs in runs.items():
        eff = [r["fps"] / (w * f) for r, (f, _) in zip(rs, serial, strict=True)]
        cpu = [c / r["cpu_per_frame"] for r, (_, c) in zip(rs, serial, strict=True)]
        rows.append(
            [
                name,
                str(w),
                f"{_med([r['fps'] for r in rs]):.1f}",
                f"{_med(eff):.2f}",
                f"{_med(cpu):.2f}",
                f"{_med([r['start_s'] for r in rs]):.1f}",
                f"{_med([r['first_progress_s'] for r in rs]):.1f}",
                str(sum(r["twice"] for r in rs)),
            ]
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--recording", help="a range-sweep recording to re-process (else made)")
    ap.add_argument("--chunk-frames", type=int, default=500, help="re-processing chunks")
    args = ap.parse_args()
    all_cores()
    reps = 1 if args.quick else args.repeats
    load_before = os.getloadavg()[0]
    spec = study_spec(16 if args.quick else 96)
    study_serial, study = [], {1: [], 2: []}
    for _ in range(reps):
        study_serial.append(serial_study(spec))
        for w in study:
            study[w].append(study_run(spec, w))
    rows = _rows("study", study_serial, study)
    n_rec = 600 if args.quick else 3000
    # the simulated recording is deterministic (seed 4): made once, kept in the temporary
    # directory for the next run
    rec = Path(args.recording or Path(tempfile.gettempdir()) / f"tofpose-bench-sweep-{n_rec}.h5")
    if not rec.exists():
        make_recording(rec, n_rec)
    for tracking in (False, True):
        serial, runs = [], {1: [], 2: []}
        for _ in range(reps):
            serial.append(serial_estimate(rec, tracking))
            for w in runs:
                runs[w].append(reprocess_run(rec, w, tracking, args.chunk_frames))
        mode = "tracking" if tracking else "acquisition"
        rows += _rows(f"re-processing, {mode}", serial, runs)
        chunks = runs[1][0]["chunks"]
    cli = [study_example_cli(2) for _ in range(reps)]
    load_after = os.getloadavg()[0]
    print(
        f"Medians of {reps} repeats; each repeat runs the serial reference, then 1 and 2 "
        f"workers, so every ratio compares runs minutes apart on the same machine. This "
        f"2-core machine is shared with other developers' test runs (load average "
        f"{load_before:.1f} at the start, {load_after:.1f} at the end): absolute frames/s "
        "are noisy, the ratios much less so, and the CPU efficiency (serial CPU seconds "
        "per frame over a worker's) hardly at all."
    )
    print()
    print(
        f"study: {spec.n_frames} frames (4 cells at 3 and 6 m, ideal and lens blur; "
        f"chunks of {spec.chunk_frames}); re-processing: a {n_rec}-frame range sweep in "
        f"{chunks} chunks of {args.chunk_frames} (its CSV is estimate's byte for byte); "
        "serial = the same frames in one process without Dask (`tofpose estimate` for "
        "re-processing). Cluster start: a LocalCluster opened in a process that opened "
        "one before, as the server does for every job after its first (its forkserver, "
        "which imported the task modules, still runs); the command line's start in a "
        "fresh process is given below."
    )
    print(
        table(
            [
                "work",
                "workers",
                "frames/s once up",
                "per-worker efficiency",
                "CPU efficiency",
                "cluster start (s)",
                "first progress (s)",
                "tasks run twice",
            ],
            rows,
        )
    )
    print()
    print(
        "Why workers were slower (bench/scaleout_workers.py): thread CPU time and minor "
        "page faults per frame of the same chunks serially and in a worker, with Dask's "
        "default worker environment and with ours"
    )
    causes = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "scaleout_workers.py"), "--recording", str(rec)],
        capture_output=True,
        text=True,
        check=True,
    )
    print(causes.stdout.strip())
    loads = [x for r in study.values() for run in r for x in run["loads"]]
    misses = sum(x["cache_misses"] for x in loads)
    first = [x["first_frame_s"] for x in loads if x["first_frame_s"] is not None]
    print()
    print(
        f"numba kernels on the study workers: {len(loads)} worker starts, cache misses "
        f"{misses} (0 = every kernel loaded from the cache, none compiled); a worker's first "
        f"frame, which loads them, took {min(first):.1f}-{max(first):.1f} s"
    )
    print()
    print(
        f"`tofpose study --example` (192 frames) on 2 workers from the command line: "
        f"{_med([c['wall_s'] for c in cli]):.1f} s in all, of which "
        f"{_med([c['start_s'] for c in cli]):.1f} s starting the cluster; first progress "
        f"{_med([c['first'] for c in cli]):.1f} s after the study started (medians of {reps})"
    )
    print()
    task_ms = scheduler_overhead_ms(500 if args.quick else 2000)
    chunk_ms, chunk_kb = store_chunk_ms()
    per_frame_s = 1.0 / _med([f for f, _ in study_serial])
    print(
        f"scheduler: {task_ms:.2f} ms per no-op task (round trip, 2 local workers); "
        f"store: {chunk_ms:.1f} ms and {chunk_kb:.0f} kB per chunk of 25 frames"
    )
    frames = 1e7
    core_h = frames * per_frame_s / 3600
    chunk = 100
    task_s = chunk * per_frame_s
    max_workers = task_s / (task_ms / 1e3)
    print()
    print(
        f"On paper, from these numbers: 10^7 frames are {core_h:.0f} core-hours "
        f"({per_frame_s * 1e3:.0f} ms a frame); on 10 nodes of 16 cores about "
        f"{core_h / 160:.1f} h. In chunks of {chunk} frames a task runs {task_s:.0f} s, "
        f"so the scheduler ({task_ms:.2f} ms a task here; Dask documents ~1 ms) saturates "
        f"near {max_workers:.0f} workers; the store takes {chunk_kb * chunk / 25:.0f} kB "
        f"a task, {chunk_kb * chunk / 25 * max_workers / task_s / 1e3:.0f} MB/s at that "
        "scale. Larger chunks move the limit out."
    )
    print()
    live = live_rates(10.0 if args.quick else 20.0)
    print(json.dumps(live), file=sys.stderr)
    print(
        f"the live loop (server, simulated camera at 10 Hz) from outside: "
        f"{live['idle_hz']:.2f} frames/s idle, {live['busy_hz']:.2f} frames/s while a study "
        f"ran on {live['cluster']} at nice +10 ({live['study_fps']:.1f} study frames/s)"
    )


if __name__ == "__main__":
    main()
