"""``tofpose import mcap``: HDF5 -> MCAP -> HDF5 keeps frames bit-exact and poses exact;
an MCAP file from elsewhere imports from its own topics; bad input is named."""

from __future__ import annotations

import foxglove
import h5py
import numpy as np
import pytest
from foxglove import messages as fm
from foxglove.channels import CameraCalibrationChannel, RawImageChannel

from tofpose.cli import main
from tofpose.core.camera import CameraModel
from tofpose.io.interop import topics
from tofpose.io.interop.channels import json_channel
from tofpose.io.interop.foxglove_messages import camera_calibration, pose_payload, timestamp
from tofpose.io.interop.mcap_import import McapImportError, import_mcap
from tofpose.io.recording import open_recording


def datasets(path) -> dict[str, np.ndarray]:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(
            lambda n, o: out.__setitem__(n, o[...]) if isinstance(o, h5py.Dataset) else None
        )
        attrs = {k: f["camera"].attrs[k] for k in f["camera"].attrs}
        catalog = f["catalog"].attrs["json"] if "catalog" in f else None
    return out, attrs, catalog


def test_round_trip_is_exact_and_gives_the_same_poses(recording, exported, tmp_path):
    back = tmp_path / "back.h5"
    assert main(["import", "mcap", str(exported), "--out", str(back)]) == 0
    a, cam_a, cat_a = datasets(recording)
    b, cam_b, cat_b = datasets(back)
    assert (
        sorted(a)
        == sorted(b)
        == sorted(
            [
                "frames/gray",
                "frames/distance_mm",
                "frames/time_s",
                "truth/R_camera_target",
                "truth/t_camera_target_mm",
                "reference/R_camera_target",
                "reference/t_camera_target_mm",
            ]
        )
    )
    for name in a:
        assert a[name].dtype == b[name].dtype, name
        np.testing.assert_array_equal(a[name], b[name], strict=True, err_msg=name)
    assert {k: np.asarray(v).tolist() for k, v in cam_a.items()} == {
        k: np.asarray(v).tolist() for k, v in cam_b.items()
    }
    assert cat_a == cat_b
    # the poses of the re-processed import are those of the source, to the last digit
    csv_a, csv_b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["estimate", str(recording), "--out", str(csv_a)]) == 0
    assert main(["estimate", str(back), "--out", str(csv_b)]) == 0
    assert csv_a.read_bytes() == csv_b.read_bytes()
    assert csv_a.read_text().count("\n") == 9


def test_an_mcap_written_before_the_rename_imports_its_lab_truth_as_the_reference(tmp_path):
    """A file of the older naming, written here channel by channel: the lab's reference
    on ``/tofpose/lab_truth`` becomes the recording's ``/reference``."""
    camera = CameraModel(width=8, height=6, fx=10.0, fy=11.0, cx=3.5, cy=2.5)
    ctx = foxglove.Context()
    gray_ch = RawImageChannel(topics.GRAY, context=ctx)
    dist_ch = RawImageChannel(topics.DISTANCE, context=ctx, metadata={"unit": "mm"})
    calib_ch = CameraCalibrationChannel(topics.CALIBRATION, context=ctx)
    old_ch = json_channel("/tofpose/lab_truth", topics.POSE_SCHEMA, ctx)
    t_reference_mm = [[5.0, -2.0, 1000.0 + i] for i in range(3)]
    src = tmp_path / "old.mcap"
    with foxglove.open_mcap(src, context=ctx):
        for i, t_mm in enumerate(t_reference_mm):
            ns = 1_700_000_000_000_000_000 + i * 50_000_000
            ts = timestamp(ns)
            calib_ch.log(camera_calibration(camera, ts), log_time=ns)
            gray = np.full((6, 8), 100 + i, "<u2")
            dist = np.full((6, 8), 1000.0 + i, "<f4")
            for ch, img, enc in ((gray_ch, gray, "16UC1"), (dist_ch, dist, "32FC1")):
                ch.log(
                    fm.RawImage(
                        timestamp=ts,
                        frame_id="camera",
                        width=8,
                        height=6,
                        encoding=enc,
                        step=8 * img.itemsize,
                        data=img.tobytes(),
                    ),
                    log_time=ns,
                )
            old_ch.log(pose_payload(i, np.eye(3), np.array(t_mm)), log_time=ns)
    out = tmp_path / "old.h5"
    assert import_mcap(src, out, progress=False) == {"frames": 3}
    with h5py.File(out) as f:
        assert "reference" in f and "lab_truth" not in f and "truth" not in f
    with open_recording(out) as rec:
        np.testing.assert_array_equal(rec.reference_t_mm, t_reference_mm)
        np.testing.assert_array_equal(rec.reference_R, np.tile(np.eye(3), (3, 1, 1)))
        assert rec.truth_R is None


def _foreign_mcap(path, n=3, bad_frame=None):
    """An MCAP written by another tool: its own topics, distance in metres (Foxglove's
    32FC1 convention), a CameraCalibration, no tofpose metadata."""
    camera = CameraModel(
        width=8, height=6, fx=10.0, fy=11.0, cx=3.5, cy=2.5, dist=(0.1, -0.01, 0.0, 0.0, 0.0)
    )
    ctx = foxglove.Context()
    gray_ch = RawImageChannel("/cam/amplitude", context=ctx)
    depth_ch = RawImageChannel("/cam/depth", context=ctx)
    calib_ch = CameraCalibrationChannel("/cam/info", context=ctx)
    rng = np.random.default_rng(1)
    truth = []
    with foxglove.open_mcap(path, context=ctx):
        for i in range(n):
            ns = 1_700_000_000_000_000_000 + i * 50_000_000
            ts = timestamp(ns)
            gray = rng.integers(0, 4096, (6, 8)).astype("<u2")
            if i == bad_frame:  # a frame of another size, part-way through the file
                gray = gray[:, :6].copy()
            depth_m = rng.uniform(0.5, 3.0, (6, 8)).astype("<f4")
            depth_m[0, 0] = np.nan
            truth.append((gray, depth_m, ns))
            calib_ch.log(camera_calibration(camera, ts), log_time=ns)
            gray_ch.log(
                fm.RawImage(
                    timestamp=ts,
                    frame_id="cam",
                    width=gray.shape[1],
                    height=6,
                    encoding="16UC1",
                    step=2 * gray.shape[1],
                    data=gray.tobytes(),
                ),
                log_time=ns,
            )
            depth_ch.log(
                fm.RawImage(
                    timestamp=ts,
                    frame_id="cam",
                    width=8,
                    height=6,
                    encoding="32FC1",
                    step=32,
                    data=depth_m.tobytes(),
                ),
                log_time=ns,
            )
    return camera, truth


def test_an_mcap_from_elsewhere_imports_from_its_own_topics(tmp_path):
    src = tmp_path / "foreign.mcap"
    camera, truth = _foreign_mcap(src)
    with pytest.raises(McapImportError, match=r"/cam/amplitude.*--gray-topic"):
        import_mcap(src, tmp_path / "x.h5", progress=False)
    out = tmp_path / "foreign.h5"
    s = import_mcap(
        src, out, gray_topic="/cam/amplitude", distance_topic="/cam/depth", progress=False
    )
    assert s == {"frames": 3}
    with open_recording(out) as rec:
        assert rec.camera.to_dict() == {**camera.to_dict(), "name": "mcap"}
        assert rec.catalog is None and rec.truth_R is None
        for i, (gray, depth_m, ns) in enumerate(truth):
            g, d, t = rec.frame(i)
            np.testing.assert_array_equal(g, gray)
            np.testing.assert_allclose(d, depth_m.astype(np.float64) * 1000.0, rtol=1e-6)
            assert np.isnan(d[0, 0])
            assert t == pytest.approx(ns * 1e-9)


def test_bad_input_is_named_and_an_existing_output_survives(exported, tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    keep = tmp_path / "keep.h5"
    keep.write_bytes(b"precious")
    assert main(["import", "mcap", str(junk), "--out", str(keep), "--force"]) == 2
    assert "not a readable MCAP file" in capsys.readouterr().err
    assert keep.read_bytes() == b"precious"
    assert main(["import", "mcap", str(exported), "--out", str(keep)]) == 2
    assert "exists" in capsys.readouterr().err
    with pytest.raises(McapImportError, match="no distance topic '/nope'"):
        import_mcap(exported, tmp_path / "y.h5", distance_topic="/nope", progress=False)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(exported.read_bytes()[: exported.stat().st_size // 2])
    with pytest.raises(McapImportError, match=str(truncated.name)):
        import_mcap(truncated, tmp_path / "z.h5", progress=False)
    assert not list(tmp_path.glob("*.partial"))


def test_a_bad_frame_part_way_leaves_the_existing_output_alone(tmp_path):
    src = tmp_path / "bad.mcap"
    _foreign_mcap(src, n=4, bad_frame=2)
    keep = tmp_path / "keep.h5"
    keep.write_bytes(b"precious")
    with pytest.raises(McapImportError, match=r"at log time \d+ ns: images \(6, 6\)"):
        import_mcap(
            src,
            keep,
            gray_topic="/cam/amplitude",
            distance_topic="/cam/depth",
            progress=False,
            overwrite=True,
        )
    assert keep.read_bytes() == b"precious"
    assert not list(tmp_path.glob("*.partial"))
