"""Studies on real Dask clusters: a LocalCluster of worker processes on loopback, and a
``dask scheduler`` + ``dask worker`` pair started as subprocesses. The same spec gives
the same summary.json, byte for byte, on 1 worker, 2 workers, the external pair, and
when a worker is killed mid-study; an unreachable scheduler is named; Ctrl-C leaves a
store that says it is incomplete and resumes."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tofpose.batch.cluster import ClusterError, dask_client
from tofpose.study.run import run_study
from tofpose.study.spec import StudySpec
from tofpose.study.store import StudyStoreError, present_chunks, read_frames, read_manifest

BIN = Path(sys.executable).parent
DOC = {
    "name": "t",
    "seed": 3,
    "frames_per_cell": 6,
    "chunk_frames": 2,
    "grid": {"range_m": [3.0, 6.0], "physics": ["ideal", "lens blur"]},
}
SPEC = StudySpec.from_dict(DOC)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# 96 one-frame tasks: an interruption lands mid-study (with 24, warm workers finished the
# whole study within a loaded machine's poll, before the test's Ctrl-C)
FINE = {**DOC, "frames_per_cell": 24, "chunk_frames": 1}
FINE_FRAMES = 96


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """The spec run on one worker."""
    out = tmp_path_factory.mktemp("one") / "study"
    run_study(SPEC, out, workers=1, progress=False, report=False)
    return out


@pytest.fixture(scope="module")
def reference_fine(tmp_path_factory) -> Path:
    """``FINE`` run on one worker."""
    out = tmp_path_factory.mktemp("fine") / "study"
    run_study(StudySpec.from_dict(FINE), out, workers=1, progress=False, report=False)
    return out


def test_one_worker_gives_a_complete_store_and_a_summary_of_it(reference):
    table = read_frames(reference, SPEC)
    assert table.num_rows == SPEC.n_frames == 24
    assert sorted(zip(table["cell"].to_pylist(), table["frame"].to_pylist(), strict=True)) == [
        (c, i) for c in range(4) for i in range(6)
    ]
    summary = json.loads((reference / "summary.json").read_text())
    assert summary["complete"] and summary["frames_stored"] == 24
    ok = sum(c["poses"] for c in summary["cells"])
    assert ok == sum(table["ok"].to_pylist())
    near = summary["cells"][0]  # 3 m, ideal: the simulator's home ground
    assert near["label"].startswith("3 m") and near["success_pct"] == 100.0
    manifest = read_manifest(reference)
    assert manifest["status"] == "complete" and manifest["chunks_done"] == 12
    load = manifest["run"]["worker_kernel_load"]
    assert len(load) == 1 and load[0]["cache_misses"] == 0  # kernels came from numba's cache


def test_two_workers_give_identical_bytes(reference, tmp_path):
    out = tmp_path / "two"
    run_study(SPEC, out, workers=2, progress=False, report=True)
    assert (out / "summary.json").read_bytes() == (reference / "summary.json").read_bytes()
    assert read_frames(out, SPEC).equals(read_frames(reference, SPEC))
    assert read_manifest(out)["run"]["workers"] == 2
    assert (out / "report.html").read_text().count("<img") == 3
    assert (out / "report.pdf").read_bytes()[:4] == b"%PDF"


def test_an_external_scheduler_and_worker_give_identical_bytes(reference, tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sched = subprocess.Popen(
        [BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = subprocess.Popen(
        [BIN / "dask", "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        spec_path = tmp_path / "spec.json"
        spec_path.write_text(json.dumps(DOC))
        out = tmp_path / "ext"
        cli = subprocess.run(
            [BIN / "tofpose", "study", str(spec_path), "--out", str(out), "--scheduler", address],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert cli.returncode == 0, cli.stderr
        assert "24 frames in 4 cells" in cli.stdout
        assert (out / "summary.json").read_bytes() == (reference / "summary.json").read_bytes()
        assert read_manifest(out)["cluster"] == address
    finally:
        for p in (worker, sched):
            p.terminate()
            p.wait(timeout=30)


def test_a_worker_killed_mid_study_changes_nothing(reference_fine, tmp_path):
    from dask.distributed import Client, LocalCluster

    spec = StudySpec.from_dict(FINE)
    ref = reference_fine
    out = tmp_path / "killed"
    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
        Client(cluster) as client,
    ):
        errors: list[BaseException] = []

        def run() -> None:
            try:
                run_study(
                    spec, out, scheduler=cluster.scheduler_address, progress=False, report=False
                )
            except BaseException as exc:  # noqa: BLE001 (reported below)
                errors.append(exc)

        th = threading.Thread(target=run)
        th.start()
        deadline = time.monotonic() + 120
        while len(present_chunks(out)) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        done_before_kill = len(present_chunks(out))
        pids = client.run(os.getpid)
        os.kill(next(iter(pids.values())), signal.SIGKILL)
        th.join(timeout=300)
        assert not errors, errors
    assert 3 <= done_before_kill < FINE_FRAMES
    assert (out / "summary.json").read_bytes() == (ref / "summary.json").read_bytes()
    files = sorted(p.name for p in (out / "frames").iterdir())
    assert len(files) == FINE_FRAMES and not [f for f in files if f.endswith(".tmp")]
    assert sum(pq.read_table(out / "frames" / f).num_rows for f in files) == FINE_FRAMES


def test_an_unreachable_scheduler_is_named():
    port = _free_port()
    with (
        pytest.raises(ClusterError, match=f"tcp://127.0.0.1:{port}"),
        dask_client(scheduler=f"tcp://127.0.0.1:{port}"),
    ):
        pass


def test_a_directory_of_another_study_is_refused(reference):
    other = StudySpec.from_dict({**DOC, "seed": 4})
    with pytest.raises(StudyStoreError, match="another study spec"):
        run_study(other, reference, workers=1, progress=False)


def test_ctrl_c_leaves_an_incomplete_store_that_resumes(reference_fine, tmp_path):
    spec_path = tmp_path / "spec.json"
    spec_path.write_text(json.dumps(FINE))
    out = tmp_path / "study"
    proc = subprocess.Popen(
        [BIN / "tofpose", "study", str(spec_path), "--out", str(out), "--workers", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    # interrupt at the first stored chunk: the 96 one-frame chunks of this spec take a few
    # seconds once the worker is up
    while not present_chunks(out) and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    manifest = read_manifest(out)
    kept = present_chunks(out)
    assert manifest["status"] == "incomplete" and 1 <= len(kept) < FINE_FRAMES
    assert not (out / "summary.json").exists()
    # the same command again runs only what is missing, to the same result
    cmd = [BIN / "tofpose", "study", str(spec_path), "--out", str(out), "--workers", "1"]
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert read_manifest(out)["status"] == "complete"
    assert read_manifest(out)["run"]["frames_run"] == FINE_FRAMES - len(kept)
    assert (out / "summary.json").read_bytes() == (reference_fine / "summary.json").read_bytes()
