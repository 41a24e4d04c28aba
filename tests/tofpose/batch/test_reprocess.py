"""Re-processing in chunks on Dask: the concatenated CSV is ``tofpose estimate``'s byte
for byte (acquisition and tracking, with the filter's columns), on a real LocalCluster of
2 worker processes; a chunk whose state never catches up is run again from the previous
chunk's origin and the output is still exact; bad input is named."""

from __future__ import annotations

import json
import os

import pytest

from tofpose.batch.reprocess import ReprocessError, Settings, plan, reprocess, synced_frame
from tofpose.cli import main
from tofpose.io.recording import RecordingError


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    sweep, grid = d / "sweep.h5", d / "grid.h5"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "range-sweep",
                "--frames",
                "90",
                "--out",
                str(sweep),
                "--seed",
                "2",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "simulate",
                "--scenario",
                "attitude-grid",
                "--frames",
                "60",
                "--out",
                str(grid),
                "--seed",
                "3",
            ]
        )
        == 0
    )
    return sweep, grid


def _estimate(rec, out, *flags) -> bytes:
    assert main(["estimate", str(rec), "--out", str(out), *flags]) == 0
    return out.read_bytes()


@pytest.mark.parametrize("n_frames", [1, 29, 30, 31, 100])
@pytest.mark.parametrize("tracking", [False, True])
def test_the_plan_outputs_each_frame_once_after_a_warm_up(n_frames, tracking):
    cs = plan("r.h5", n_frames, 30, 5, tracking, 15)
    assert [i for c in cs for i in range(c.start, c.stop)] == list(range(n_frames))
    for prev, c in zip(cs, cs[1:], strict=False):
        assert c.origin <= c.start - 4  # at least the persistence history
        if tracking:
            assert c.origin % 15 == 0 and (c.start - c.origin >= 4 + 15 or c.origin == 0)
        assert prev.tail == c.start - c.origin  # the previous chunk digests the warm-up
        assert prev.stop - prev.tail == c.origin
    assert cs[0].origin == 0


@pytest.mark.parametrize("tracking", [False, True])
def test_two_workers_reproduce_estimate_byte_for_byte(recordings, tmp_path, tracking):
    sweep, grid = recordings
    flags = ["--tracking"] if tracking else []
    serial = {
        r.stem: _estimate(r, tmp_path / f"{r.stem}.csv", *flags, "--filter") for r in recordings
    }
    out = tmp_path / "out"
    s = reprocess(
        [str(sweep), str(grid)],
        out,
        settings=Settings(tracking=tracking),
        workers=2,
        filter_state=True,
        chunk_frames=20,
        progress=False,
    )
    for r in recordings:
        assert (out / f"{r.stem}.csv").read_bytes() == serial[r.stem]
    assert s["run"]["workers"] == 2
    # two workers read ahead only on a host with a core to spare for each reader
    assert s["run"]["read_ahead"] == (len(os.sched_getaffinity(0)) >= 4)
    rec = {r["csv"]: r for r in s["recordings"]}
    assert rec["sweep.csv"]["chunks"] == 5 and len(rec["sweep.csv"]["boundaries"]) == 4
    assert json.loads((out / "reprocess.json").read_text())["filter"] is True
    # how each recording was measured: estimate's defaults, the learned prior's numbers
    for r in s["recordings"]:
        assert r["pixel_fit"] is True
        assert r["range_bias"] is not None and r["range_bias"]["n_frames"] >= 8
        assert r["range_bias_summary"].startswith("range bias learned over")
        # the prior the frames were measured with: never wider than the configured one
        # unless the recording showed more
        assert 0 < r["range_bias_sigma_mm"] <= max(15.0, r["range_bias"]["sigma_mm"])
        assert (
            r["range_bias_sigma_mm"] == pytest.approx(min(r["range_bias"]["sigma_mm"], 15.0))
            or r["range_bias"]["tau_mm"] ** 2 - 2 * r["range_bias"]["tau2_se_mm2"] > 15.0**2
        )


def test_a_cancel_during_the_range_bias_learning_stops_before_any_chunk_runs(recordings, tmp_path):
    from tofpose.batch.reprocess import ReprocessCancelledError

    sweep, _ = recordings
    polls = []

    def stop_at_the_third_poll():
        polls.append(1)
        return len(polls) >= 3  # once before the learning, then inside it

    with pytest.raises(ReprocessCancelledError):
        reprocess(
            [str(sweep)],
            tmp_path / "out",
            workers=1,
            progress=False,
            should_stop=stop_at_the_third_poll,
        )
    assert not (tmp_path / "out" / "chunks").exists()


def test_a_camera_with_a_covariance_scale_is_measured_with_the_centroid_pose_and_its_priors(
    recordings, tmp_path
):
    """A covariance scale calibrates the centroid pose's covariance under the configured
    priors: reprocess and estimate then measure without the pixel fit and without a
    learned range bias, both alike, and say so."""
    from tofpose.calibration.covariance import CovarianceScale
    from tofpose.core.camera import CameraModel

    sweep, _ = recordings
    cam = tmp_path / "scaled.json"
    scale = CovarianceScale((1000.0, 4000.0), (0.5, 0.8))
    cam.write_text(json.dumps({**CameraModel().to_dict(), "covariance_scale": scale.to_dict()}))
    serial = _estimate(sweep, tmp_path / "serial.csv", "--camera", str(cam))
    s = reprocess(
        [str(sweep)],
        tmp_path / "out",
        settings=Settings(camera_path=str(cam)),
        workers=1,
        chunk_frames=40,
        progress=False,
    )
    assert (tmp_path / "out" / "sweep.csv").read_bytes() == serial
    (r,) = s["recordings"]
    assert r["pixel_fit"] is False and r["range_bias"] is None
    # asked for, the pixel fit runs with that camera too
    asked = _estimate(sweep, tmp_path / "asked.csv", "--camera", str(cam), "--pixel-fit")
    assert asked != serial


def test_a_chunk_that_never_catches_up_runs_on_from_the_previous_origin(
    recordings, tmp_path, monkeypatch
):
    """Workers in this process (threads), with digests that never agree: every boundary
    falls back, and the CSV is still exact."""
    from dask.distributed import LocalCluster

    from tofpose.pipeline import PosePipeline

    sweep, _ = recordings
    serial = _estimate(sweep, tmp_path / "serial.csv")
    monkeypatch.setattr(PosePipeline, "state_digest", lambda self: os.urandom(16))
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        s = reprocess(
            [str(sweep)],
            tmp_path / "out",
            scheduler=cluster.scheduler_address,
            chunk_frames=30,
            progress=False,
        )
    assert (tmp_path / "out" / "sweep.csv").read_bytes() == serial
    b = s["recordings"][0]["boundaries"]
    assert [x.get("continued_from_frame") for x in b] == [0, 0]  # each from chunk 0's origin
    assert s["run"]["chunks_run_again"] == 2


def test_synced_frame_finds_the_first_equal_digest():
    cs = plan("r.h5", 60, 30, 5, False, 15)
    prev, cur = cs
    tail = [f"t{i}" for i in range(prev.tail)]
    warm = ["w"] * (cur.start - cur.origin)
    assert synced_frame(prev, {"tail": tail}, cur, {"warm": warm}) is None
    warm[3] = tail[3]
    assert synced_frame(prev, {"tail": tail}, cur, {"warm": warm}) == cur.origin + 3


def test_bad_input_is_named(recordings, tmp_path):
    sweep, _ = recordings
    with pytest.raises(RecordingError, match="nope.h5: no such file"):
        reprocess([str(tmp_path / "nope.h5")], tmp_path / "o", workers=1, progress=False)
    other = tmp_path / "x"
    other.mkdir()
    (other / "sweep.h5").write_bytes(sweep.read_bytes())
    with pytest.raises(ReprocessError, match="two recordings are named 'sweep'"):
        reprocess([str(sweep), str(other / "sweep.h5")], tmp_path / "o", workers=1)
    assert main(["reprocess", str(sweep), "--out", str(tmp_path / "o"), "--chunk-frames", "0"]) == 2
