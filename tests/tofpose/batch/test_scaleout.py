"""Re-processing and studies on a real LocalCluster, as fast as they can be made without
changing a result: a tracking re-processing of a recording whose track begins out of
phase with the chunks gives estimate's poses byte for byte and runs each chunk exactly
once (counted in Dask's task stream); a running chunk reports progress before it ends;
more workers than cores is said; the workers run without Dask's malloc trim threshold
and with one numeric thread."""

from __future__ import annotations

import json
import threading
import time
from collections import Counter

import numpy as np
import pytest

from tofpose.batch.cluster import (
    ClusterWarning,
    open_cluster,
    oversubscription_warnings,
    spare_core_per_thread,
)
from tofpose.batch.reprocess import Settings, plan, reprocess
from tofpose.cli import main
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.io.camera_file import pipeline_for
from tofpose.io.recording import RecordingWriter, open_recording
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene
from tofpose.study.run import run_study
from tofpose.study.spec import StudySpec
from tofpose.study.store import read_manifest

DARK_FRAMES = 7  # the first pose at frame 7: out of phase with the period of 15
FRAMES = 80
CHUNK = 20


@pytest.fixture(scope="module")
def late_track(tmp_path_factory):
    """A recording whose first frames are dark (no pose), then a target at 3 m turning
    slowly: the tracker acquires it at frame 7 and keeps it."""
    path = tmp_path_factory.mktemp("rec") / "late.h5"
    cam = CameraModel()
    rng = np.random.default_rng(4)
    dark = (np.zeros(cam.shape, np.uint16), np.full(cam.shape, np.nan, np.float32))
    with RecordingWriter(path, cam, paper_target()) as w:
        for i in range(FRAMES):
            if i < DARK_FRAMES:
                w.append(*dark, i / 10)
                continue
            R = rotation_from_euler_deg(1.0, -2.0, 5.0 + 0.05 * i) @ R_FACING
            T = RigidTransform(R, np.array([0.0, -30.0, 3000.0]))
            f = render_frame(cam, TargetScene(), T, SensorModel(), rng)
            w.append(f.gray, f.distance_mm, i / 10)
    return path


def _serial_modes(path) -> list[str | None]:
    """What ``estimate --tracking`` does with each frame: its mode, None without a pose."""
    modes: list[str | None] = []
    with open_recording(path) as rec:
        pipe = pipeline_for(rec, str(path), None, None, True)
        for _, (g, d, ts) in rec.blocks(0, rec.n_frames):
            for k, t in enumerate(ts.tolist()):
                r = pipe.process(g[k], d[k], t)
                modes.append(r.mode if r.ok else None)
    return modes


def test_a_tracking_reprocess_gives_estimates_poses_and_runs_each_chunk_once(late_track, tmp_path):
    from dask.distributed import get_task_stream

    modes = _serial_modes(late_track)
    # the premise: the track begins at frame 7 and every chunk boundary is inside it
    assert modes[:DARK_FRAMES] == [None] * DARK_FRAMES and modes[DARK_FRAMES] == "acquisition"
    assert all(modes[b - 1] == "tracking" for b in range(CHUNK, FRAMES, CHUNK))
    assert main(["estimate", str(late_track), "--out", str(tmp_path / "e.csv"), "--tracking"]) == 0
    with open_cluster(workers=2) as session, get_task_stream(session.client) as stream:
        s = reprocess(
            [str(late_track)],
            tmp_path / "out",
            settings=Settings(tracking=True),
            chunk_frames=CHUNK,
            progress=False,
            session=session,
        )
    assert (tmp_path / "out" / "late.csv").read_bytes() == (tmp_path / "e.csv").read_bytes()
    runs = Counter(t["key"].rsplit("-", 1)[-1] for t in stream.data if "reprocess" in t["key"])
    planned = plan(str(late_track), FRAMES, CHUNK, 5, True, 15)
    assert runs == {f"{c.start:08d}": 1 for c in planned}  # each chunk once, none again
    assert s["run"]["chunks_run_again"] == 0
    assert all("synced_at_frame" in b for b in s["recordings"][0]["boundaries"])


def _reporting_task(topic: str) -> int:
    """A task that reports 3 frames done, then waits for the client to let it end."""
    from distributed import Event

    from tofpose.batch.worker import ProgressReporter

    ProgressReporter(topic, "chunk-a")(3)
    Event("tofpose-test-go").wait(timeout=120)
    return 3


def test_the_client_hears_of_a_running_tasks_frames_before_it_ends():
    """The task reports and then waits on an event only the client sets once it has
    heard: progress reaches the client while the task runs."""
    from distributed import Event

    from tofpose.batch.progress import RunProgress

    with open_cluster(workers=1) as session, RunProgress(session.client) as live:
        fut = session.client.submit(_reporting_task, live.topic, pure=False)
        deadline = time.monotonic() + 120
        while live.running_frames() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert live.running_frames() == 3 and not fut.done()
        Event("tofpose-test-go", client=session.client).set()
        assert fut.result() == 3
        live.finished("chunk-a")
        assert live.running_frames() == 0


def test_a_reprocessing_reports_its_frames_as_they_are_done(late_track, tmp_path):
    seen: list[int] = []
    s = reprocess(
        [str(late_track)],
        tmp_path / "out",
        workers=1,
        chunk_frames=CHUNK,
        progress=False,
        on_progress=lambda done, total: seen.append(done),
    )
    assert seen == sorted(seen) and seen[-1] == FRAMES
    assert s["run"]["first_progress_s"] is not None


def test_a_study_chunk_moves_study_json_while_it_runs(tmp_path):
    """One cell, one chunk of 96 frames (~2 s): study.json's frames_done takes values
    between 0 and 96 while the study is running."""
    spec = StudySpec.from_dict(
        {"name": "one", "seed": 2, "frames_per_cell": 96, "chunk_frames": 96, "grid": {}}
    )
    out = tmp_path / "study"
    seen: set[int] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            try:
                m = json.loads((out / "study.json").read_text())
            except (OSError, ValueError):
                m = {}
            if m.get("status") == "running":
                seen.add(m.get("frames_done", 0))
            time.sleep(0.01)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        run_study(spec, out, workers=1, progress=False, report=False)
    finally:
        done.set()
        watcher.join()
    assert any(0 < n < 96 for n in seen), seen
    m = read_manifest(out)
    assert m["status"] == "complete" and m["frames_done"] == 96
    assert 0 < m["run"]["first_progress_s"] <= m["run"]["wall_s"]


def test_more_workers_than_cores_is_said_per_host():
    infos = [
        {"host": "a", "cores": 2, "threads": 1},
        {"host": "a", "cores": 2, "threads": 1},
        {"host": "a", "cores": 2, "threads": 1},
        {"host": "b", "cores": 4, "threads": 2},
    ]
    (said,) = oversubscription_warnings(infos)
    assert said.startswith("3 worker threads on a, which has 2 cores")
    assert oversubscription_warnings(infos[:2]) == []


def test_tasks_read_ahead_only_where_every_worker_thread_has_a_core_to_spare():
    one_of_two = [{"host": "a", "cores": 2, "threads": 1}]
    assert spare_core_per_thread(one_of_two)
    assert not spare_core_per_thread(one_of_two * 2)  # two workers share two cores
    assert not spare_core_per_thread([{"host": "a", "cores": 4, "threads": 3}])
    mixed = [{"host": "a", "cores": 4, "threads": 2}, {"host": "b", "cores": 2, "threads": 2}]
    assert not spare_core_per_thread(mixed)  # host b has none to spare
    assert spare_core_per_thread(mixed[:1])
    assert not spare_core_per_thread([])


def test_a_local_cluster_of_more_workers_than_cores_warns_and_its_workers_are_set_up():
    import os

    cores = len(os.sched_getaffinity(0))
    names = ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "NUMBA_NUM_THREADS")
    said = pytest.warns(ClusterWarning, match=f"{cores + 1} worker threads on .* {cores} cores")
    with said, open_cluster(workers=cores + 1) as session:
        env = session.client.run(lambda: {k: os.environ.get(k) for k in names})
        assert len(session.warnings) == 1 and session.workers == cores + 1
        assert not session.read_ahead
        assert session.dashboard_url is not None
        assert session.dashboard_url.startswith("http://127.0.0.1:")
    expected = {"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    assert all(e == expected for e in env.values())


def test_the_command_line_says_when_workers_outnumber_the_cores(late_track, tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    cores = len(os.sched_getaffinity(0))
    exe = Path(sys.executable).with_name("tofpose")
    cmd = [exe, "reprocess", late_track, "--out", tmp_path / "o", "--workers", str(cores + 1)]
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"ClusterWarning: {cores + 1} worker threads on" in done.stderr
    assert f"which has {cores} cores" in done.stderr
