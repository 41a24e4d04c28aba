"""Scale-out on Dask (docs/scaleout.md; docs/results.md, "Scale-out on Dask"): what a
study and a re-processing run do per second on 1 and 2 workers of this machine, against
the same work in one process without Dask; whether workers load the numba kernels from
the cache; what a task costs the scheduler and a chunk costs the store; and the live
camera loop's frame rate while a study runs in the server.

Each throughput is the median of ``--repeats`` runs, counted from the cluster's start to
the last chunk (start-up itself is reported apart); the serial baseline measures the same
frames in this process (kernels already loaded). Scaling efficiency = rate on 2 workers /
(2 x rate on 1 worker).

Run: ``python bench/scaleout.py [--repeats 3] [--quick]``
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


def serial_study_fps(spec: StudySpec) -> float:
    """The spec's frames measured in this process, no Dask: frames / s."""
    kernel_load()
    cam = CameraModel()
    t0 = time.perf_counter()
    for c in spec.cells:
        for i in range(spec.frames_per_cell):
            measure_frame(spec, c, i, cam)
    return spec.n_frames / (time.perf_counter() - t0)


def study_runs(spec: StudySpec, workers: int, repeats: int) -> dict:
    from tofpose.study.run import run_study
    from tofpose.study.store import read_manifest

    fps, warm, start, loads = [], [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as d:
            run_study(spec, Path(d) / "s", workers=workers, progress=False, report=False)
            run = read_manifest(Path(d) / "s")["run"]
            fps.append(run["frames_per_s"])
            warm.append(run["frames_per_s_warm"])
            start.append(run["cluster_start_s"])
            loads += run["worker_kernel_load"]
    return {
        "fps": float(np.median(fps)),
        "warm": float(np.median(warm)),
        "start_s": float(np.median(start)),
        "loads": loads,
    }


def make_recording(path: Path, n: int) -> None:
    from tofpose.cli import simulate

    simulate("range-sweep", n, str(path), 4, None, progress=False)


def serial_estimate_fps(rec: Path, tracking: bool) -> float:
    from tofpose.cli import estimate

    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        s = estimate(
            str(rec), str(Path(d) / "e.csv"), None, None, progress=False, tracking=tracking
        )
        return s["frames"] / (time.perf_counter() - t0)


def reprocess_fps(rec: Path, workers: int, tracking: bool, repeats: int) -> tuple:
    """Medians: (frames/s after the cluster's start, frames/s once warm, chunks run
    again %)."""
    from tofpose.batch.reprocess import Settings, reprocess

    fps, warm, extra = [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as d:
            s = reprocess(
                [str(rec)],
                d,
                settings=Settings(tracking=tracking),
                workers=workers,
                chunk_frames=100,
                progress=False,
            )
            fps.append(s["run"]["frames_per_s"])
            warm.append(s["run"]["frames_per_s_warm"])
            chunks = max(1, s["recordings"][0]["chunks"])
            extra.append(100.0 * s["run"]["chunks_run_again"] / chunks)
    return float(np.median(fps)), float(np.median(warm)), float(np.median(extra))


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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    all_cores()
    reps = 1 if args.quick else args.repeats
    spec = study_spec(12 if args.quick else 64)
    serial = serial_study_fps(spec)
    runs = {w: study_runs(spec, w, reps) for w in (1, 2)}
    rows = [["serial (one process, no Dask)", "-", f"{serial:.1f}", "-", f"{serial:.1f}", "-"]]
    for w, r in runs.items():
        eff = r["fps"] / (w * runs[1]["fps"])
        rows.append(
            [
                f"LocalCluster, {w} worker{'s' if w > 1 else ''}",
                f"{r['start_s']:.1f}",
                f"{r['fps']:.1f}",
                f"{eff:.2f}",
                f"{r['warm']:.1f}",
                f"{r['warm'] / (w * runs[1]['warm']):.2f}",
            ]
        )
    print(
        f"study: {spec.n_frames} frames ({len(spec.cells)} cells at 3 and 6 m, ideal and "
        f"lens blur; chunks of {spec.chunk_frames}); medians of {reps} runs"
    )
    print(
        table(
            [
                "run",
                "cluster start (s)",
                "frames/s after start",
                "scaling efficiency",
                "frames/s once warm",
                "scaling efficiency (warm)",
            ],
            rows,
        )
    )
    loads = [x for r in runs.values() for x in r["loads"]]
    misses = sum(x["cache_misses"] for x in loads)
    secs = [x["seconds"] for x in loads]
    print()
    print(
        f"numba kernels on the workers: {len(loads)} worker starts, cache misses {misses} "
        f"(0 = every kernel loaded from the cache, none compiled), warm-up "
        f"{min(secs):.1f}-{max(secs):.1f} s per worker"
    )
    print()
    n_rec = 240 if args.quick else 3000
    with tempfile.TemporaryDirectory() as d:
        rec = Path(d) / "sweep.h5"
        make_recording(rec, n_rec)
        rrows = []
        for tracking in (False, True):
            s = serial_estimate_fps(rec, tracking)
            r1, w1, _ = reprocess_fps(rec, 1, tracking, reps)
            r2, w2, again = reprocess_fps(rec, 2, tracking, reps)
            mode = "tracking" if tracking else "acquisition"
            eff = f"{r2 / (2 * r1):.2f} ({w2 / (2 * w1):.2f})"
            rrows.append(
                [
                    mode,
                    f"{s:.1f}",
                    f"{r1:.1f} ({w1:.1f})",
                    f"{r2:.1f} ({w2:.1f})",
                    eff,
                    f"{again:.0f} %",
                ]
            )
    print(
        f"re-processing a {n_rec}-frame recording (range sweep) in chunks of 100, "
        f"medians of {reps} runs (the CSV is estimate's byte for byte); frames/s after "
        "the cluster's start (in brackets: once warm, over the chunks' own time)"
    )
    print(
        table(
            [
                "mode",
                "tofpose estimate (frames/s)",
                "1 worker",
                "2 workers",
                "scaling efficiency",
                "chunks run again",
            ],
            rrows,
        )
    )
    print()
    task_ms = scheduler_overhead_ms(500 if args.quick else 2000)
    chunk_ms, chunk_kb = store_chunk_ms()
    per_frame_s = 1.0 / serial
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
