"""A recording on demand carries each frame's latency stamps (/frames/capture_ns,
arrival_ns, pose_ready_ns and their UTC anchor) and reads them back; a recording without
them (an older file, ``tofpose simulate``'s) still reads, without stamps."""

from __future__ import annotations

import dataclasses
import time

import h5py
import numpy as np
import pytest

from backend.services.live.hub import LiveHub
from backend.services.live.latency import FrameStamps
from backend.services.recordings import RecordingService
from tests.backend.services.test_recordings import CAMERA, make_sample
from tofpose.core.catalog import paper_target
from tofpose.io.recording import STAMP_DATASETS, RecordingWriter, open_recording


@pytest.fixture
def service(tmp_path):
    hub = LiveHub()
    svc = RecordingService(tmp_path / "recordings", hub, CAMERA, paper_target, min_free_mb=0)
    yield svc, hub
    svc.stop_all()


def test_stamps_are_written_and_read_back(service):
    svc, hub = service
    rng = np.random.default_rng(3)
    base_ns = time.monotonic_ns()
    sent = []
    for i in range(12):
        capture = base_ns + i * 50_000_000  # a frame every 50 ms
        stamps = FrameStamps(capture, capture + 7_000_000 + i, capture + 30_000_000 + 2 * i)
        sent.append(dataclasses.replace(make_sample(i, rng), stamps=stamps))
    info = svc.start("stamps")
    wall_before = time.time_ns()
    for s in sent:
        hub.publish(s)
    done = svc.stop(info.id)
    assert done.frames == 12
    with open_recording(svc.directory / done.file) as rec:
        st = rec.stamps
        assert st is not None
        np.testing.assert_array_equal(st.capture_ns, [s.stamps.capture_ns for s in sent])
        np.testing.assert_array_equal(st.arrival_ns, [s.stamps.arrival_ns for s in sent])
        np.testing.assert_array_equal(st.pose_ready_ns, [s.stamps.pose_ready_ns for s in sent])
        assert st.capture_ns.dtype == np.int64
        # the anchor puts the first capture (taken just before the recording) at UTC now
        first_wall = int(st.wall_ns(st.capture_ns[:1])[0])
        assert abs(first_wall - wall_before) < 5e9
        np.testing.assert_array_equal(np.diff(st.wall_ns(st.capture_ns)), np.full(11, 50_000_000))


def test_a_recording_without_stamps_reads_without_them(tmp_path):
    path = tmp_path / "old.h5"
    with RecordingWriter(path, CAMERA) as w:
        for i in range(3):
            w.append(np.zeros((30, 40), np.uint16), np.ones((30, 40), np.float32), 0.1 * i)
    with open_recording(path) as rec:
        assert rec.n_frames == 3 and rec.stamps is None
    # stamps for only some frames (a file cut off part-way): not trusted, still readable
    with h5py.File(path, "a") as f:
        for name in STAMP_DATASETS:
            f.create_dataset(name, data=np.arange(2, dtype=np.int64))
        f["frames"].attrs["monotonic_anchor_ns"] = 0
        f["frames"].attrs["wall_anchor_ns"] = 0
    with open_recording(path) as rec:
        assert rec.n_frames == 3 and rec.stamps is None
