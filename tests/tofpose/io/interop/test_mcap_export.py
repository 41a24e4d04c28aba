"""``tofpose export mcap``: read back with the ``mcap`` library's reader, every channel
decoded with the schema it declares (protobuf by ``mcap-protobuf-support`` from the file's
own descriptors, JSON validated against the file's own JSON schema), compared with the
HDF5 source and with the pipeline run on the same frames."""

from __future__ import annotations

import json
from collections import defaultdict

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tofpose.cli import main
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import rotation_from_quaternion_wxyz
from tofpose.io.interop import topics
from tofpose.io.interop.mcap_export import export_mcap
from tofpose.io.interop.previews import distance_to_bgr, gray_to_u8
from tofpose.io.recording import RecordingWriter, open_recording
from tofpose.pipeline import PosePipeline

PER_FRAME = {
    topics.GRAY: "foxglove.RawImage",
    topics.DISTANCE: "foxglove.RawImage",
    topics.GRAY_PREVIEW: "foxglove.RawImage",
    topics.DISTANCE_PREVIEW: "foxglove.RawImage",
    topics.CALIBRATION: "foxglove.CameraCalibration",
    topics.ANNOTATIONS: "foxglove.ImageAnnotations",
    topics.FRAME: "tofpose.Frame",
    topics.ESTIMATE: "tofpose.Estimate",
    topics.REFLECTORS: "foxglove.PointCloud",
    topics.TRUTH: "tofpose.Pose",
    topics.TRUTH_TRANSFORM: "foxglove.FrameTransform",
    topics.REFERENCE: "tofpose.Pose",
    topics.REFERENCE_TRANSFORM: "foxglove.FrameTransform",
}
PER_POSE = {
    topics.POSE_TRANSFORM: "foxglove.FrameTransform",
    topics.POSE: "foxglove.PoseInFrame",
    topics.TARGET_ORIGIN: "foxglove.PointCloud",
}


def read_back(path):
    """{topic: [(log_time_ns, decoded)]}, {topic: (schema name, schema encoding, channel
    metadata)}, metadata records: decoded by the schema each channel declares."""
    factory, out, channels = DecoderFactory(), defaultdict(list), {}
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            channels[channel.topic] = (schema.name, schema.encoding, dict(channel.metadata))
            if schema.encoding == "jsonschema":
                assert channel.message_encoding == "json"
                payload = json.loads(message.data)
                jsonschema.validate(payload, json.loads(schema.data))
            else:
                assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf")
                payload = factory.decoder_for(channel.message_encoding, schema)(message.data)
            out[channel.topic].append((message.log_time, payload))
    return out, channels, metadata


@pytest.fixture(scope="module")
def contents(exported):
    return read_back(exported)


@pytest.fixture(scope="module")
def results(recording):
    """The pipeline's results on the recording's frames, as the export ran it."""
    with open_recording(recording) as rec:
        pipe = PosePipeline(rec.camera, rec.catalog)
        return [pipe.process(*rec.frame(i)) for i in range(rec.n_frames)]


def test_every_channel_has_the_declared_schema_and_one_message_per_frame(contents, results):
    messages, channels, _ = contents
    n_ok = sum(r.ok for r in results)
    assert 6 <= n_ok < len(results)  # some frames with a pose, one without
    assert any(r.rejected for r in results) and any(r.unmatched for r in results)
    assert {t: c[0] for t, c in channels.items()} == {**PER_FRAME, **PER_POSE}
    for topic in PER_FRAME:
        assert len(messages[topic]) == len(results), topic
    for topic in PER_POSE:
        assert len(messages[topic]) == n_ok, topic


def test_the_trail_channel_is_each_poses_target_origin_in_metres(contents, results):
    messages, _, _ = contents
    with_pose = [r for r in results if r.ok]
    origins = messages[topics.TARGET_ORIGIN]
    pose_times = [t for t, _ in messages[topics.POSE_TRANSFORM]]
    assert [t for t, _ in origins] == pose_times
    for (_t, cloud), r in zip(origins, with_pose, strict=True):
        assert [f.name for f in cloud.fields] == ["x", "y", "z"] and cloud.point_stride == 12
        assert cloud.frame_id == topics.CAMERA_FRAME_ID
        xyz = np.frombuffer(cloud.data, "<f4")
        np.testing.assert_array_equal(xyz, (r.t_mm / 1000.0).astype(np.float32))


def test_images_are_the_recordings_frames_at_their_capture_times(recording, contents):
    messages, channels, _ = contents
    assert channels[topics.DISTANCE][2] == topics.DISTANCE_CHANNEL_METADATA
    with open_recording(recording) as rec:
        for i, ((t_gray, g), (t_dist, d)) in enumerate(
            zip(messages[topics.GRAY], messages[topics.DISTANCE], strict=True)
        ):
            gray, dist, time_s = rec.frame(i)
            assert t_gray == t_dist == round(time_s * 1e9)
            assert (g.encoding, g.width, g.height, g.step) == ("mono16", 320, 240, 640)
            assert (d.encoding, d.step) == ("32FC1", 1280)
            assert g.timestamp.seconds * 10**9 + g.timestamp.nanos == t_gray
            np.testing.assert_array_equal(np.frombuffer(g.data, "<u2").reshape(240, 320), gray)
            np.testing.assert_array_equal(
                np.frombuffer(d.data, "<f4").reshape(240, 320), dist, strict=True
            )
            frame = messages[topics.FRAME][i][1]
            assert frame == {"index": i, "time_s": time_s}


def test_previews_are_what_a_viewer_should_show(recording, contents):
    messages, _, _ = contents
    with open_recording(recording) as rec:
        gray, dist, _ = rec.frame(2)
    g = messages[topics.GRAY_PREVIEW][2][1]
    assert (g.encoding, g.step) == ("mono8", 320)
    shown = np.frombuffer(g.data, np.uint8).reshape(240, 320)
    np.testing.assert_array_equal(shown, gray_to_u8(gray))
    assert shown.max() > 4 * (gray.max() // 256)  # 12-bit counts are visible in 8 bits
    d = messages[topics.DISTANCE_PREVIEW][2][1]
    assert (d.encoding, d.step) == ("rgb8", 960)
    rgb = np.frombuffer(d.data, np.uint8).reshape(240, 320, 3)
    np.testing.assert_array_equal(rgb, distance_to_bgr(dist)[..., ::-1])
    valid = np.isfinite(dist)
    assert np.all(rgb[~valid] == 0) and len(np.unique(rgb[valid].reshape(-1, 3), axis=0)) > 50


def test_estimates_are_the_pipelines_and_the_transforms_agree(contents, results):
    messages, _, _ = contents
    transforms = iter(messages[topics.POSE_TRANSFORM])
    poses = iter(messages[topics.POSE])
    for (_ns, est), r in zip(messages[topics.ESTIMATE], results, strict=True):
        assert (est["ok"], est["reason"], est["n_matched"]) == (r.ok, r.reason, r.n_matched)
        if not r.ok:
            assert est["R_camera_target"] is None
            continue
        assert est["R_camera_target"] == r.R.ravel().tolist()  # exact
        assert est["t_camera_target_mm"] == r.t_mm.tolist()
        assert est["covariance"] == r.covariance.ravel().tolist()
        assert [m["id"] for m in est["matched"]] == [m.catalog_id for m in r.matched]
        np.testing.assert_allclose(est["sigma_mm"], np.sqrt(np.diag(r.covariance))[3:])
        _, tf = next(transforms)
        assert (tf.parent_frame_id, tf.child_frame_id) == ("camera", "target")
        t = tf.translation
        np.testing.assert_allclose([t.x, t.y, t.z], r.t_mm / 1000.0, rtol=0, atol=1e-12)
        q = tf.rotation
        R = rotation_from_quaternion_wxyz([q.w, q.x, q.y, q.z])
        np.testing.assert_allclose(R, r.R, atol=1e-12)
        _, pose = next(poses)
        assert pose.frame_id == "camera"
        assert pose.pose.position.z == pytest.approx(r.t_mm[2] / 1000.0, abs=1e-12)


def test_reference_poses_are_exact(recording, contents):
    messages, _, _ = contents
    with open_recording(recording) as rec:
        for topic, tf_topic, R_all, t_all in (
            (topics.TRUTH, topics.TRUTH_TRANSFORM, rec.truth_R, rec.truth_t_mm),
            (topics.REFERENCE, topics.REFERENCE_TRANSFORM, rec.reference_R, rec.reference_t_mm),
        ):
            for i, ((_, pose), (_, tf)) in enumerate(
                zip(messages[topic], messages[tf_topic], strict=True)
            ):
                assert pose["R_camera_target"] == R_all[i].ravel().tolist()
                assert pose["t_camera_target_mm"] == t_all[i].tolist()
                assert tf.translation.x == pytest.approx(t_all[i][0] / 1000.0, abs=1e-12)


def test_reflectors_and_overlay_show_the_matches(contents, results):
    messages, _, _ = contents
    for r, (_, cloud), (_, ann) in zip(
        results, messages[topics.REFLECTORS], messages[topics.ANNOTATIONS], strict=True
    ):
        names = [f.name for f in cloud.fields]
        assert names[:3] == ["x", "y", "z"] and "id" in names
        dtype = np.dtype(
            [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("id", "<u4"), ("residual_mm", "<f4")]
        )
        assert cloud.point_stride == dtype.itemsize
        pts = np.frombuffer(cloud.data, dtype)
        assert pts["id"].tolist() == [m.catalog_id for m in r.matched]
        for p, m in zip(pts, r.matched, strict=True):
            np.testing.assert_allclose([p["x"], p["y"], p["z"]], m.point_mm / 1000.0, rtol=1e-6)
        assert len(ann.circles) == len(r.matched) + len(r.unmatched) + len(r.rejected)
        labels = [t.text for t in ann.texts]
        assert labels[: len(r.matched)] == [str(m.catalog_id) for m in r.matched]
        assert labels[len(r.matched) :] == [rb.reason for rb in r.rejected]
        for c, m in zip(ann.circles[: len(r.matched)], r.matched, strict=True):
            # Foxglove's image origin is the top-left corner of the top-left pixel
            assert (c.position.x, c.position.y) == pytest.approx(tuple(m.centroid_uv + 0.5))


def test_camera_model_and_metadata(recording, contents):
    messages, _, metadata = contents
    with open_recording(recording) as rec:
        cam, catalog = rec.camera, rec.catalog
    _, calib = messages[topics.CALIBRATION][0]
    assert list(calib.K) == [cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1]
    assert calib.distortion_model == "plumb_bob" and list(calib.D) == list(cam.dist)
    meta = metadata[topics.METADATA_NAME]
    assert meta["format"] == "tofpose-mcap" and meta["n_frames"] == "8"
    assert Catalog.from_json(meta["catalog"]) == catalog
    assert json.loads(meta["recording_camera"]) == cam.to_dict()
    assert json.loads(meta["pipeline_config"])["refinement"] == "ml"
    assert meta["has_truth"] == meta["has_reference"] == "true"


def test_no_estimate_writes_frames_only(recording, tmp_path):
    out = tmp_path / "frames.mcap"
    assert main(["export", "mcap", str(recording), "--out", str(out), "--no-estimate"]) == 0
    messages, channels, metadata = read_back(out)
    assert topics.ESTIMATE not in channels and topics.ANNOTATIONS not in channels
    assert len(messages[topics.GRAY]) == 8
    assert metadata[topics.METADATA_NAME]["pipeline_config"] == ""


def test_existing_output_is_kept_and_bad_times_are_named(recording, tmp_path, capsys, camera):
    out = tmp_path / "keep.mcap"
    out.write_bytes(b"precious")
    assert main(["export", "mcap", str(recording), "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_bytes() == b"precious"
    bad = tmp_path / "negative.h5"
    with RecordingWriter(bad, camera) as w:
        z = np.zeros((camera.height, camera.width))
        w.append(z.astype(np.uint16), z.astype(np.float32), -0.5)
    with open_recording(bad) as rec, pytest.raises(ValueError, match=r"-0\.5 s"):
        export_mcap(rec, tmp_path / "neg.mcap")
    assert not (tmp_path / "neg.mcap").exists()
