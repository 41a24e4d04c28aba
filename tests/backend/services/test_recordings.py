"""Recordings on demand (backend/services/recordings.py), fed by a hub the test publishes
to: the file holds exactly the frames the hub delivered, with their poses, covariances,
relative states, references, encoder readings and wall-clock stamps; it opens with
``tofpose.io.recording`` and exports to an MCAP that ``mcap``'s reader reads; the recording
stops on request, after its duration, when the disk fills (file closed and readable) and
is refused from the start without enough free space."""

from __future__ import annotations

import json
import shutil
import time
from collections import namedtuple

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from backend.drivers.base import AxisLimits, CameraFrame, MotionStatus
from backend.services import recordings
from backend.services.campaigns.mcap_files import recording_mcap
from backend.services.live.acquisition import LiveSample
from backend.services.live.hub import LiveHub
from backend.services.motion import MotionService
from backend.services.recordings import (
    InsufficientSpaceError,
    RecordingConflictError,
    RecordingService,
    RecordingState,
    StopReason,
)
from tests.backend.conftest import wait_for
from tests.tofpose.io.interop.test_mcap_export import read_back
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.io.interop import topics
from tofpose.io.recording import open_recording
from tofpose.lab.relative_state import RelativeState
from tofpose.pipeline import PoseResult

CAMERA = CameraModel(width=40, height=30, fx=40.0, fy=40.0, cx=19.5, cy=14.5, name="small")
AXES = {
    "yaw": AxisLimits("yaw", "deg", -170, 170, 20),
    "rail": AxisLimits("rail", "mm", 0, 13000, 100),
}
Usage = namedtuple("Usage", "total used free")
PLENTY = Usage(10**12, 0, 10**12)


class TableDriver:
    """A motion driver whose status the test knows: targets (yaw 12, rail 300), busy."""

    name = "table"
    axes = AXES

    def __init__(self) -> None:
        self.reads = 0

    def status(self) -> MotionStatus:
        self.reads += 1
        return MotionStatus(
            {"yaw": 11.5, "rail": 250.0}, {"yaw": 12.0, "rail": 300.0}, busy=True, settled=False
        )


def make_sample(
    i: int,
    rng: np.random.Generator,
    *,
    captured_unix_s: float | None = None,
    ok: bool = True,
    state: bool = True,
) -> LiveSample:
    """Sample ``i``: random images, a random pose with a covariance, references, the
    relative state (or none) and the encoders at the frame."""
    R = Rotation.random(random_state=rng).as_matrix()
    t = rng.normal(0.0, 500.0, 3) + [0.0, 0.0, 5000.0]
    A = rng.normal(size=(6, 6))
    result = (
        PoseResult(
            True,
            time_s=0.05 * i,
            R=R,
            t_mm=t,
            covariance=A @ A.T,
            residual_mm=float(rng.uniform(0.1, 2.0)),
        )
        if ok
        else PoseResult(False, "too few reflectors", 0.05 * i)
    )
    B = rng.normal(size=(12, 12))
    rel = (
        RelativeState(
            0.05 * i,
            R,
            t,
            rng.normal(size=3),
            rng.normal(size=3),
            rng.normal(size=3),
            B @ B.T,
            "updated",
        )
        if state
        else None
    )
    frame = CameraFrame(
        gray=rng.integers(0, 4096, (30, 40)).astype(np.uint16),
        distance_mm=rng.uniform(300.0, 15000.0, (30, 40)).astype(np.float32),
        time_s=0.05 * i,
        index=1000 + i,
        T_camera_target_exact=RigidTransform(R, t),
        T_camera_target_lab=RigidTransform(R, t + 1.0),
        meta={"encoders": {"yaw": 0.1 * i, "rail": 100.0 + i}},
    )
    captured = time.time() if captured_unix_s is None else captured_unix_s
    return LiveSample(frame, result, "paper-target", captured, captured + 0.01, state=rel)


@pytest.fixture
def hub():
    return LiveHub()


@pytest.fixture
def motion():
    return MotionService(TableDriver())


@pytest.fixture
def service(tmp_path, hub, motion):
    svc = RecordingService(
        tmp_path / "recordings", hub, CAMERA, paper_target, motion, min_free_mb=1000
    )
    yield svc
    svc.stop_all()


def test_every_frame_the_hub_delivers_is_written_with_pose_state_motion_and_stamps(service, hub):
    rng = np.random.default_rng(7)
    info = service.start("before the test")
    assert info.state is RecordingState.RECORDING and hub.n_subscribers == 1
    sent = [make_sample(i, rng, ok=i % 4 != 3, state=i > 1) for i in range(30)]
    for s in sent:
        hub.publish(s)
    done = service.stop(info.id)

    assert (done.state, done.stop_reason, done.frames) == (
        RecordingState.STOPPED,
        StopReason.REQUESTED,
        30,
    )
    assert hub.n_subscribers == 0 and done.dropped_frames == 0
    path = service.directory / done.file
    assert done.size_bytes == path.stat().st_size > 0
    with open_recording(path) as rec:
        assert rec.n_frames == 30 and rec.camera == CAMERA and rec.catalog == paper_target()
        np.testing.assert_array_equal(rec.time_s, [s.frame.time_s for s in sent])
        for k in (0, 17, 29):
            gray, dist, _ = rec.frame(k)
            np.testing.assert_array_equal(gray, sent[k].frame.gray)
            np.testing.assert_array_equal(dist, sent[k].frame.distance_mm)
        np.testing.assert_array_equal(rec.truth_R, [s.frame.T_camera_target_exact.R for s in sent])
        np.testing.assert_array_equal(
            rec.reference_t_mm, [s.frame.T_camera_target_lab.t_mm for s in sent]
        )
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["frames/index"][...], [s.frame.index for s in sent])
        np.testing.assert_array_equal(
            f["frames/wall_time_ns"][...], [round(s.captured_unix_s * 1e9) for s in sent]
        )
        ok = np.array([s.result.ok for s in sent])
        np.testing.assert_array_equal(f["pose/ok"][...], ok)
        assert [r.decode() for r in f["pose/reason"][...]] == [s.result.reason for s in sent]
        poses = [s.result for s in sent if s.result.ok]
        np.testing.assert_array_equal(f["pose/R_camera_target"][ok], [p.R for p in poses])
        np.testing.assert_array_equal(f["pose/t_camera_target_mm"][ok], [p.t_mm for p in poses])
        np.testing.assert_array_equal(f["pose/covariance"][ok], [p.covariance for p in poses])
        assert np.isnan(f["pose/covariance"][~ok]).all()
        assert np.isnan(f["pose/R_camera_target"][~ok]).all()
        has = np.array([s.state is not None for s in sent])
        np.testing.assert_array_equal(f["relative_state/valid"][...], has)
        states = [s.state for s in sent if s.state is not None]
        group = f["relative_state"]
        np.testing.assert_array_equal(group["covariance"][has], [s.covariance for s in states])
        np.testing.assert_array_equal(
            group["angular_rate_deg_s"][has], [s.angular_rate_deg_s for s in states]
        )
        np.testing.assert_array_equal(
            group["velocity_mm_s"][has], [s.velocity_mm_s for s in states]
        )
        assert np.isnan(f["relative_state/covariance"][~has]).all()
        # the encoders at each frame, the targets of the status read at most every 0.2 s
        assert list(f["motion"].attrs["axes"]) == ["yaw", "rail"]
        assert list(f["motion"].attrs["units"]) == ["deg", "mm"]
        np.testing.assert_array_equal(
            f["motion/positions"][...], [[0.1 * i, 100.0 + i] for i in range(30)]
        )
        np.testing.assert_array_equal(f["motion/targets"][...], [[12.0, 300.0]] * 30)
        assert f["motion/busy"][...].all()
        status_ns = f["motion/status_wall_time_ns"][...]
        started_ns = info.started_utc.timestamp() * 1e9
        assert ((status_ns >= started_ns - 1e6) & (status_ns <= time.time() * 1e9)).all()
        assert f.attrs["name"] == "before the test" and f.attrs["recording_id"] == info.id
    # the index on disk says the same
    index = json.loads((service.directory / "index.json").read_text())
    assert index["recordings"][0]["frames"] == 30
    assert index["recordings"][0]["state"] == "stopped"


def test_the_recording_exports_to_an_mcap_that_mcaps_reader_reads(service, hub, tmp_path):
    rng = np.random.default_rng(3)
    info = service.start("for a colleague")
    sent = [make_sample(i, rng) for i in range(5)]
    for s in sent:
        hub.publish(s)
    path = service.file(service.stop(info.id).id)
    messages, _, _ = read_back(recording_mcap(path))  # every message decoded by its schema
    assert len(messages[topics.GRAY]) == 5
    for k, (_, msg) in enumerate(messages[topics.GRAY]):
        np.testing.assert_array_equal(
            np.frombuffer(msg.data, "<u2").reshape(30, 40), sent[k].frame.gray
        )
    np.testing.assert_allclose(
        [p["t_camera_target_mm"] for _, p in messages[topics.TRUTH]],
        [s.frame.T_camera_target_exact.t_mm for s in sent],
    )


def test_start_is_refused_below_the_free_space_floor(service, hub, monkeypatch):
    monkeypatch.setattr(shutil, "disk_usage", lambda _p: Usage(10**12, 10**12, 999 * 10**6))
    with pytest.raises(InsufficientSpaceError, match=r"999 MB free .* below the floor of 1000 MB"):
        service.start("too late")
    assert service.list() == [] and hub.n_subscribers == 0


def test_a_filling_disk_stops_the_recording_with_the_file_closed_and_readable(
    service, hub, monkeypatch
):
    calls = []

    def usage(_path):  # one call at start, then one before each frame: the 8th frame sees it full
        calls.append(1)
        return PLENTY if len(calls) <= 8 else Usage(10**12, 10**12, 10 * 10**6)

    monkeypatch.setattr(shutil, "disk_usage", usage)
    rng = np.random.default_rng(11)
    info = service.start("during a problem")
    for i in range(20):
        hub.publish(make_sample(i, rng))
    done = wait_for(
        lambda: (i := service.get(info.id)).state is RecordingState.STOPPED and i,
        what="the recording to stop on the full disk",
    )
    assert done.stop_reason is StopReason.DISK_FULL
    assert "10 MB free" in done.stop_detail and "1000 MB" in done.stop_detail
    assert done.frames == 7 and hub.n_subscribers == 0
    with open_recording(service.directory / done.file) as rec:
        assert rec.n_frames == 7
    with h5py.File(service.directory / done.file, "r") as f:
        assert {f[n].shape[0] for n in ("frames/index", "pose/covariance", "motion/targets")} == {7}


def test_a_duration_stops_the_recording_at_the_first_frame_after_its_end(service, hub):
    rng = np.random.default_rng(5)
    info = service.start("short", duration_s=30.0)
    t0 = info.started_utc.timestamp()
    for i in range(4):
        hub.publish(make_sample(i, rng, captured_unix_s=t0 + 5.0 * i))  # 0, 5, 10, 15 s
    hub.publish(make_sample(4, rng, captured_unix_s=t0 + 30.5))  # after the end: not written
    done = wait_for(
        lambda: (i := service.get(info.id)).state is RecordingState.STOPPED and i,
        what="the recording's end",
    )
    assert (done.stop_reason, done.frames) == (StopReason.DURATION, 4)
    assert "duration of 30 s" in done.stop_detail


def test_a_duration_stops_the_recording_without_frames_too(service):
    info = service.start("nothing comes", duration_s=0.2)
    done = wait_for(
        lambda: (i := service.get(info.id)).state is RecordingState.STOPPED and i,
        what="the recording's end",
    )
    assert (done.stop_reason, done.frames) == (StopReason.DURATION, 0)
    with open_recording(service.directory / done.file) as rec:  # an empty file, readable
        assert rec.n_frames == 0


def test_at_most_max_active_record_at_once(service):
    a, _b = service.start("a"), service.start("b")
    with pytest.raises(RecordingConflictError, match=r"at most 2 at once"):
        service.start("c")
    service.stop(a.id)
    assert service.start("c").id == 3
    assert [i.name for i in service.list()] == ["c", "b", "a"]


def test_a_write_failing_part_way_is_cut_off_and_stops_the_recording(service, hub, monkeypatch):
    rng = np.random.default_rng(2)
    real, calls = recordings.frame_row, []

    def broken(*args):
        row = real(*args)
        calls.append(1)
        if len(calls) == 4:  # the frame and references are written, then this fails
            del row["pose/covariance"]
        return row

    monkeypatch.setattr(recordings, "frame_row", broken)
    info = service.start("broken")
    for i in range(6):
        hub.publish(make_sample(i, rng))
    done = wait_for(
        lambda: (i := service.get(info.id)).state is RecordingState.STOPPED and i,
        what="the recording to stop",
    )
    assert done.stop_reason is StopReason.ERROR and "pose/covariance" in done.stop_detail
    assert done.frames == 3
    with h5py.File(service.directory / done.file, "r") as f:
        lengths = set()
        f.visititems(lambda _n, o: lengths.add(o.shape[0]) if isinstance(o, h5py.Dataset) else None)
        assert lengths == {3}


def test_a_recording_left_running_by_a_dead_server_is_found_interrupted(tmp_path, hub, motion):
    directory = tmp_path / "recordings"
    svc = RecordingService(directory, hub, CAMERA, paper_target, motion, min_free_mb=0)
    rng = np.random.default_rng(1)
    info = svc.start("crash")
    for i in range(3):
        hub.publish(make_sample(i, rng))
    svc.stop(info.id)
    index = json.loads((directory / "index.json").read_text())
    index["recordings"][0].update(state="recording", frames=0, stop_reason=None)  # as left
    (directory / "index.json").write_text(json.dumps(index))

    again = RecordingService(directory, hub, CAMERA, paper_target, motion, min_free_mb=0)
    found = again.get(info.id)
    assert found.state is RecordingState.STOPPED
    assert (found.stop_reason, found.frames) == (StopReason.INTERRUPTED, 3)
    assert again.start("next").id == info.id + 1
    again.stop_all()


def test_delete_removes_the_files_and_the_entry_but_not_while_recording(service, hub):
    info = service.start("gone soon")
    with pytest.raises(RecordingConflictError, match="stop it first"):
        service.delete(info.id)
    hub.publish(make_sample(0, np.random.default_rng(0)))
    path = service.file(service.stop(info.id).id)
    exports = [recording_mcap(path), recording_mcap(path, profile="ros2")]
    assert [p.name for p in exports] == [f"{path.stem}.mcap", f"{path.stem}.ros2.mcap"]
    assert all(p.exists() and p.with_name(p.name + ".json").exists() for p in exports)
    assert service.used_bytes >= sum(p.stat().st_size for p in [path, *exports])
    service.delete(info.id)
    assert sorted(path.parent.glob(f"{path.stem}.*")) == []  # HDF5, both exports, notes
    assert service.list() == []
    # a new recording never reuses a deleted one's id
    assert service.start("new").id == info.id + 1


def test_a_recording_writes_the_camera_model_as_it_is_when_it_starts(tmp_path, hub, motion):
    """The live camera's model follows its settings (a new modulation frequency: where
    its distances wrap); a recording started after a change writes the new one as
    ``/camera``, so that a replay measures with it."""
    from dataclasses import replace as replaced

    now = {"model": CAMERA}
    svc = RecordingService(
        tmp_path / "recordings", hub, lambda: now["model"], paper_target, motion, min_free_mb=0
    )
    try:
        rng = np.random.default_rng(3)
        paths = []
        for mhz in (6.0, 24.0):
            now["model"] = replaced(CAMERA, modulation_frequency_hz=mhz * 1e6)
            info = svc.start(f"at {mhz:g} MHz")
            for i in range(3):
                hub.publish(make_sample(i, rng))
            paths.append(svc.directory / svc.stop(info.id).file)
        for path, mhz in zip(paths, (6.0, 24.0), strict=True):
            with open_recording(path) as rec:
                assert rec.camera.modulation_frequency_hz == mhz * 1e6
    finally:
        svc.stop_all()


def test_a_frame_at_another_modulation_frequency_stops_the_recording_and_says_why(
    tmp_path, hub, motion
):
    """A recording holds one camera model: its ``/camera`` is the model its first frame
    was taken with (the sample's, not the camera's now, which may have moved on), and a
    frame taken at another modulation frequency (a campaign's set-point, say) stops it
    with ``camera_changed``, every earlier frame kept and readable."""
    from dataclasses import replace as replaced

    at_6 = replaced(CAMERA, modulation_frequency_hz=6e6)
    at_24 = replaced(CAMERA, modulation_frequency_hz=24e6)
    # the camera says 24 MHz already; the frames delivered so far were taken at 6
    svc = RecordingService(
        tmp_path / "recordings", hub, lambda: at_24, paper_target, motion, min_free_mb=0
    )
    try:
        rng = np.random.default_rng(5)
        info = svc.start("over a change")
        for i in range(3):
            hub.publish(replaced(make_sample(i, rng), camera_model=at_6))
        hub.publish(replaced(make_sample(3, rng), camera_model=at_24))
        stopped = wait_for(
            lambda: (x := svc.get(info.id)).state is RecordingState.STOPPED and x,
            10.0,
            "the recording to stop",
        )
        assert stopped.stop_reason is StopReason.CAMERA_CHANGED
        assert "from 6 to 24 MHz" in stopped.stop_detail
        assert "after frame 3" in stopped.stop_detail and stopped.frames == 3
        with open_recording(svc.directory / stopped.file) as rec:
            assert rec.n_frames == 3
            assert rec.camera.modulation_frequency_hz == 6e6
    finally:
        svc.stop_all()
