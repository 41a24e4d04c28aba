"""Why a Dask worker ran at half a serial run's speed (docs/scaleout.md, "What a worker
costs"): the same study and re-processing chunks measured in the client's process and,
right after each, in a LocalCluster worker, once with Dask's default worker environment
(``MALLOC_TRIM_THRESHOLD_=65536`` among it) and once with ours
(``tofpose.batch.cluster.WORKER_ENVIRONMENT``): each chunk's thread CPU time and minor
page faults per frame (``getrusage(RUSAGE_THREAD)``), which other processes on a shared
machine disturb little. Medians over the chunks, after one chunk that loads the kernels.

Run: ``python bench/scaleout_workers.py [--recording REC.h5]`` (each worker environment
is measured in a process of its own: a forkserver keeps the environment it started with).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._common import table  # noqa: E402

STUDY = {
    "name": "causes",
    "seed": 11,
    "frames_per_cell": 64,
    "chunk_frames": 8,
    "grid": {"range_m": [3.0, 6.0], "physics": ["ideal", "lens blur"]},
}
CHUNKS = 6  # measured chunks of each kind, after one that loads the kernels


def _measured(task, *args) -> dict:
    """Run ``task(*args)`` (returns its frame count) in this thread: frames, CPU s and
    minor page faults of the thread."""
    r0, c0 = resource.getrusage(resource.RUSAGE_THREAD), time.thread_time()
    frames = task(*args)
    r1 = resource.getrusage(resource.RUSAGE_THREAD)
    return {
        "frames": frames,
        "cpu_s": time.thread_time() - c0,
        "faults": r1.ru_minflt - r0.ru_minflt,
    }


def study_chunk(k: int) -> int:
    from tofpose.study.frames import run_chunk

    with tempfile.TemporaryDirectory() as d:
        return run_chunk(STUDY, k % 4, 8 * (k // 4), 8 * (k // 4) + 8, d)["frames"]


def reprocess_chunk(rec: str, k: int) -> int:
    from tofpose.batch.reprocess import Chunk, Settings, run_chunk

    start = 600 + 100 * k  # inside the sweep's tracked stretch
    with tempfile.TemporaryDirectory() as d:
        run_chunk(
            # the chunk carries its measurement (reprocess resolves the settings into it)
            Chunk(rec, k, start - 30, start, start + 100, 0, pixel_fit=False),
            Settings(tracking=True, pixel_fit=False),
            d,
        )
    return 100


def _per_frame(rows: list[dict]) -> dict:
    return {
        "cpu_ms": float(np.median([1e3 * r["cpu_s"] / r["frames"] for r in rows])),
        "faults": float(np.median([r["faults"] / r["frames"] for r in rows])),
    }


def measure(where: str, rec: str) -> dict:
    """Per-frame CPU and page faults of both kinds of chunk, each run in this process and
    in a worker one after the other (so that both see the same load); ``where``: "dask"
    (the worker with Dask's default environment) or "tofpose" (ours)."""
    import tofpose.batch.cluster as cluster

    jobs = {
        "study": [(study_chunk, k) for k in range(CHUNKS + 1)],
        "re-processing": [(reprocess_chunk, rec, k) for k in range(CHUNKS + 1)],
    }
    if where == "dask":
        cluster.WORKER_ENVIRONMENT = {}  # Dask's own pre-spawn environment
        # and no mallopt at connection (open_cluster sends this function to the workers)
        import tofpose.batch.worker

        tofpose.batch.worker.relax_malloc_trim = lambda: False
    out: dict = {}
    with cluster.open_cluster(workers=1) as session:
        c = session.client
        env = c.run(lambda: __import__("os").environ.get("MALLOC_TRIM_THRESHOLD_"))
        out["MALLOC_TRIM_THRESHOLD_"] = next(iter(env.values()))
        for name, calls in jobs.items():
            here, there = [], []
            for call in calls:
                here.append(_measured(*call))
                there.append(c.submit(_measured, *call, pure=False).result())
            out[name] = {"serial": _per_frame(here[1:]), "worker": _per_frame(there[1:])}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument(
        "--recording", default=str(Path(tempfile.gettempdir()) / "tofpose-bench-sweep-3000.h5")
    )
    ap.add_argument("--where", choices=["dask", "tofpose"])
    args = ap.parse_args()
    if args.where:
        print(json.dumps(measure(args.where, args.recording)))
        return
    if not Path(args.recording).exists():
        from tofpose.workflows.simulation import simulate

        simulate("range-sweep", 3000, args.recording, 4, None, progress=False)
    got = {}
    for where in ("dask", "tofpose"):
        out = subprocess.run(
            [sys.executable, __file__, "--where", where, "--recording", args.recording],
            capture_output=True,
            text=True,
            check=True,
        )
        got[where] = json.loads(out.stdout.strip().splitlines()[-1])
    rows = []
    for name in ("study", "re-processing"):
        for where in ("dask", "tofpose"):
            trim = got[where]["MALLOC_TRIM_THRESHOLD_"]
            label = f"{where}'s (MALLOC_TRIM_THRESHOLD_={trim})"
            m = got[where][name]
            here, there = m["serial"], m["worker"]
            rows.append(
                [
                    name,
                    label,
                    f"{here['cpu_ms']:.1f}",
                    f"{there['cpu_ms']:.1f}",
                    f"{here['cpu_ms'] / there['cpu_ms']:.2f}",
                    f"{here['faults']:.0f}",
                    f"{there['faults']:.0f}",
                ]
            )
    print(
        f"per frame, medians over {CHUNKS} chunks after one that loads the kernels, each "
        "run in the client's process and then in the worker (study: "
        "chunks of 8 frames at 3 and 6 m; re-processing: tracking chunks of 100 frames of "
        "the range sweep, each after a 30-frame warm-up)"
    )
    print(
        table(
            [
                "work",
                "worker environment",
                "serial CPU ms/frame",
                "worker CPU ms/frame",
                "serial / worker",
                "serial page faults/frame",
                "worker page faults/frame",
            ],
            rows,
        )
    )


if __name__ == "__main__":
    main()
