"""``tofpose export mcap --profile ros2``: read back with ``rosbags`` (a ROS 2 reader that
shares no code with the writer, ``mcap-ros2-support``), every message decoded with the
definitions the file declares, and compared with the HDF5 source, with the pipeline and
the relative-state filter run on the same frames."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from tofpose.cli import main
from tofpose.io.interop import ros2_topics as topics
from tofpose.io.interop.mcap_profiles import export_mcap_profile
from tofpose.io.interop.ros2_schemas import definition
from tofpose.io.recording import open_recording
from tofpose.lab.motion_models import TwoModelRelativeState
from tofpose.pipeline import PosePipeline

OPTICAL = "tofpose_camera_optical_frame"  # REP 103's optical frame, as the docs name it


def read_back(path: Path) -> dict[str, list[tuple[int, object]]]:
    """{topic: [(log time ns, message)]} decoded by rosbags with the file's definitions."""
    out: dict[str, list[tuple[int, object]]] = defaultdict(list)
    with AnyReader([path]) as reader:
        for connection, log_time_ns, raw in reader.messages():
            assert connection.msgtype == topics.TYPES[connection.topic]
            out[connection.topic].append((log_time_ns, reader.deserialize(raw, connection.msgtype)))
    return out


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def rotation(q) -> np.ndarray:
    """(3, 3) of a ROS quaternion (x, y, z, w)."""
    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def ros_covariance(msg) -> np.ndarray:
    return np.asarray(msg.covariance, float).reshape(6, 6)


@pytest.fixture(scope="module")
def exported_ros2(recording):
    """``recording`` exported with the pipeline's estimates, as ROS 2 messages."""
    out = recording.with_name("rec-ros2.mcap")
    args = ["export", "mcap", str(recording), "--out", str(out), "--profile", "ros2"]
    assert main(args) == 0
    return out


@pytest.fixture(scope="module")
def ros2(exported_ros2):
    return read_back(exported_ros2)


@pytest.fixture(scope="module")
def run(recording):
    """The pipeline's results and the filter's states on the recording's frames."""
    with open_recording(recording) as rec:
        pipe = PosePipeline(rec.camera, rec.catalog)
        rel = TwoModelRelativeState()  # as the export (and estimate --filter)
        results, states = [], []
        for i in range(rec.n_frames):
            gray, dist, time_s = rec.frame(i)
            r = pipe.process(gray, dist, time_s)
            results.append(r)
            pose = (r.R, r.t_mm, r.covariance) if r.ok else (None, None, None)
            states.append(rel.step(time_s, *pose))
    return results, states


def test_file_is_a_ros2_mcap_of_cdr_messages_with_ros2msg_schemas(exported_ros2):
    with open(exported_ros2, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary is not None
    schemas = {s.id: s for s in summary.schemas.values()}
    for channel in summary.channels.values():
        schema = schemas[channel.schema_id]
        assert (channel.message_encoding, schema.encoding) == ("cdr", "ros2msg")
        assert schema.name == topics.TYPES[channel.topic]


def test_declared_definitions_are_ros2s_own(ros2):
    """Each schema the file declares parses (rosbags' .msg parser) to the same fields as
    rosbags' own store of ROS 2 Humble's types."""
    humble = get_typestore(Stores.ROS2_HUMBLE)
    for type_name in sorted(set(topics.TYPES.values())):
        declared = get_types_from_msg(definition(type_name), type_name)
        assert type_name in declared
        for name, fields in declared.items():
            assert fields == humble.fielddefs[name], name


def test_every_message_decodes_one_per_frame(recording, ros2, run):
    results, states = run
    n = len(results)
    n_ok = sum(r.ok for r in results)
    assert 0 < n_ok < n  # some frames with a pose, one without
    n_states = sum(s is not None for s in states)
    counts = {topic: len(messages) for topic, messages in ros2.items()}
    assert counts == {
        topics.AMPLITUDE: n,
        topics.DISTANCE: n,
        topics.DEPTH: n,
        topics.CAMERA_INFO: n,
        topics.POSE: n_ok,
        topics.STATE_POSE: n_states,
        topics.STATE_TWIST: n_states,
        topics.TF: n,  # the truth and lab truth of every frame, the estimate where there is one
        topics.TF_STATIC: 1,
    }


def test_images_are_the_recordings_frames_in_metres(recording, ros2):
    with open_recording(recording) as rec:
        cam = rec.camera
        v, u = np.mgrid[0 : cam.height, 0 : cam.width]
        uv = np.column_stack((u.ravel(), v.ravel())).astype(float)
        for i in range(rec.n_frames):
            gray, dist_mm, time_s = rec.frame(i)
            t_ns = round(time_s * 1e9)
            (ta, a), (td, d), (tz, z) = (
                ros2[topic][i] for topic in (topics.AMPLITUDE, topics.DISTANCE, topics.DEPTH)
            )
            assert ta == td == tz == t_ns
            for img in (a, d, z):
                assert stamp_ns(img) == t_ns and img.header.frame_id == OPTICAL
                assert (img.width, img.height, img.is_bigendian) == (320, 240, 0)
            assert (a.encoding, a.step) == ("mono16", 640)
            np.testing.assert_array_equal(a.data.view("<u2").reshape(240, 320), gray)
            assert (d.encoding, d.step) == (z.encoding, z.step) == ("32FC1", 1280)
            dist_m = d.data.view("<f4").reshape(240, 320)
            assert dist_m.dtype == np.float32
            np.testing.assert_array_equal(np.isnan(dist_m), np.isnan(dist_mm))
            # metres, to float32's precision (one rounding of the exact quotient)
            np.testing.assert_allclose(dist_m, dist_mm / 1000.0, rtol=2**-24, atol=0)
            # z depth (REP 118): the z of each pixel's back-projected point
            depth_m = z.data.view("<f4").reshape(240, 320)
            points_mm = cam.back_project(uv, dist_mm.astype(float).ravel())
            np.testing.assert_allclose(
                depth_m, points_mm[:, 2].reshape(240, 320) / 1000.0, rtol=2**-23, atol=0
            )
            valid = np.isfinite(dist_mm)
            assert np.all(depth_m[valid] <= dist_m[valid])  # z <= radial off-axis


def test_camera_info_is_the_recordings_camera(recording, ros2):
    with open_recording(recording) as rec:
        cam = rec.camera
    _, info = ros2[topics.CAMERA_INFO][0]
    assert info.header.frame_id == OPTICAL
    assert (info.width, info.height, info.distortion_model) == (320, 240, "plumb_bob")
    np.testing.assert_array_equal(info.k, [cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1])
    np.testing.assert_array_equal(info.d, cam.dist)
    np.testing.assert_array_equal(info.r, np.eye(3).ravel())
    np.testing.assert_array_equal(info.p, [cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0])


def test_poses_are_the_pipelines_in_metres(ros2, run):
    results, _ = run
    poses = iter(ros2[topics.POSE])
    for r in results:
        if not r.ok:
            continue
        _, msg = next(poses)
        assert stamp_ns(msg) == round(r.time_s * 1e9) and msg.header.frame_id == OPTICAL
        p = msg.pose.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], r.t_mm / 1000.0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(rotation(msg.pose.pose.orientation), r.R, atol=1e-14)
    assert next(poses, None) is None


def test_pose_covariance_is_in_ross_order_and_units(ros2, run):
    """ROS's (x, y, z m; rotX, rotY, rotZ rad) blocks are our (rotation vector rad,
    translation mm) blocks swapped, mm -> m."""
    results, _ = run
    ok = [r for r in results if r.ok]
    for r, (_, msg) in zip(ok, ros2[topics.POSE], strict=True):
        C, C_ros = r.covariance, ros_covariance(msg.pose)
        np.testing.assert_allclose(C_ros[:3, :3], C[3:, 3:] * 1e-6, rtol=1e-15)
        np.testing.assert_allclose(C_ros[3:, 3:], C[:3, :3], rtol=1e-15)
        np.testing.assert_allclose(C_ros[:3, 3:], C[3:, :3] * 1e-3, rtol=1e-15)
        np.testing.assert_allclose(C_ros[3:, :3], C[:3, 3:] * 1e-3, rtol=1e-15)


def test_pose_covariance_describes_rotations_about_the_header_frames_fixed_axes(ros2, run):
    """The covariance's meaning, not only its arithmetic: poses drawn from the pipeline's
    covariance (its left perturbation) and measured the way ROS defines the covariance
    (position in m; rotations about the fixed axes of the header frame: the rotation
    vector of R' R^T for small angles, i.e. the extrinsic x-y-z angles) scatter as the
    message's covariance says."""
    results, _ = run
    r = next(r for r in results if r.ok)
    _, msg = ros2[topics.POSE][0]
    rng = np.random.default_rng(7)
    draws = rng.multivariate_normal(np.zeros(6), r.covariance, size=20000)
    R_drawn = Rotation.from_rotvec(draws[:, :3]).as_matrix() @ r.R
    t_drawn_m = (r.t_mm + draws[:, 3:]) / 1000.0
    R0 = rotation(msg.pose.pose.orientation)
    p = msg.pose.pose.position
    d_xyz = t_drawn_m - [p.x, p.y, p.z]
    d_fixed = Rotation.from_matrix(R_drawn @ R0.T).as_euler("xyz")  # rotX, rotY, rotZ
    empirical = np.cov(np.column_stack((d_xyz, d_fixed)).T)
    C_ros = ros_covariance(msg.pose)
    sd = np.sqrt(np.diag(C_ros))
    # correlation and relative variance of 20000 draws: a few percent
    np.testing.assert_allclose(empirical / np.outer(sd, sd), C_ros / np.outer(sd, sd), atol=0.05)


def test_transforms_are_the_estimate_and_the_recordings_references(recording, ros2, run):
    results, _ = run
    with open_recording(recording) as rec:
        refs = {
            "tofpose_target_truth": (rec.truth_R, rec.truth_t_mm),
            "tofpose_target_reference": (rec.reference_R, rec.reference_t_mm),
        }
    for i, (r, (_, tf)) in enumerate(zip(results, ros2[topics.TF], strict=True)):
        by_child = {t.child_frame_id: t for t in tf.transforms}
        expected = {**refs, **({"tofpose_target": None} if r.ok else {})}
        assert set(by_child) == set(expected)
        for child, t in by_child.items():
            assert t.header.frame_id == OPTICAL and stamp_ns(t) == round(r.time_s * 1e9)
            R, t_mm = (r.R, r.t_mm) if child == "tofpose_target" else (a[i] for a in refs[child])
            tr = t.transform.translation
            np.testing.assert_allclose([tr.x, tr.y, tr.z], t_mm / 1000.0, rtol=0, atol=1e-15)
            np.testing.assert_allclose(rotation(t.transform.rotation), R, atol=1e-14)


def test_static_transform_is_rep103s_optical_frame_under_the_camera_link(ros2):
    (_, tf_static), *_ = ros2[topics.TF_STATIC]
    (t,) = tf_static.transforms
    assert (t.header.frame_id, t.child_frame_id) == ("tofpose_camera_link", OPTICAL)
    R = rotation(t.transform.rotation)
    # optical z (forward) is the body's x, optical x (right) its -y, optical y (down) its -z
    np.testing.assert_allclose(R @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, -1], atol=1e-15)


def test_relative_state_is_the_filters_pose_and_twist(ros2, run):
    _, states = run
    states = [s for s in states if s is not None]
    assert any(s.status == "updated" for s in states)
    for s, (_, pose), (_, twist) in zip(
        states, ros2[topics.STATE_POSE], ros2[topics.STATE_TWIST], strict=True
    ):
        assert stamp_ns(pose) == stamp_ns(twist) == round(s.time_s * 1e9)
        assert pose.header.frame_id == twist.header.frame_id == OPTICAL
        p = pose.pose.pose.position
        np.testing.assert_allclose([p.x, p.y, p.z], s.t_mm / 1000.0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(rotation(pose.pose.pose.orientation), s.R, atol=1e-14)
        v, w = twist.twist.twist.linear, twist.twist.twist.angular
        np.testing.assert_allclose([v.x, v.y, v.z], s.velocity_mm_s / 1000.0, rtol=1e-15)
        np.testing.assert_allclose([w.x, w.y, w.z], np.radians(s.angular_rate_deg_s), rtol=1e-15)
        C = s.covariance
        np.testing.assert_allclose(ros_covariance(pose.pose)[:3, :3], C[3:6, 3:6] * 1e-6)
        np.testing.assert_allclose(ros_covariance(pose.pose)[3:, 3:], C[0:3, 0:3])
        T = ros_covariance(twist.twist)  # (v m/s, w rad/s) <- ours (w rad/s, v mm/s)
        np.testing.assert_allclose(T[:3, :3], C[9:12, 9:12] * 1e-6)
        np.testing.assert_allclose(T[3:, 3:], C[6:9, 6:9])
        np.testing.assert_allclose(T[:3, 3:], C[9:12, 6:9] * 1e-3)


def test_without_estimate_only_frames_and_references(recording, tmp_path):
    out = tmp_path / "frames.mcap"
    args = ["export", "mcap", str(recording), "--out", str(out), "--profile", "ros2"]
    assert main([*args, "--no-estimate"]) == 0
    topics_found = set(read_back(out))
    assert topics_found == {
        topics.AMPLITUDE,
        topics.DISTANCE,
        topics.DEPTH,
        topics.CAMERA_INFO,
        topics.TF,
        topics.TF_STATIC,
    }


def test_an_unknown_profile_is_refused_by_name_and_writes_nothing(recording, tmp_path):
    out = tmp_path / "x.mcap"
    with (
        open_recording(recording) as rec,
        pytest.raises(ValueError, match="'ros1'.*foxglove, ros2"),
    ):
        export_mcap_profile(rec, out, profile="ros1")
    assert not out.exists()


def test_an_existing_output_is_kept_without_force(recording, tmp_path):
    out = tmp_path / "x.mcap"
    out.write_bytes(b"keep")
    with open_recording(recording) as rec, pytest.raises(ValueError, match="exists"):
        export_mcap_profile(rec, out, profile="ros2")
    assert out.read_bytes() == b"keep"


def test_import_mcap_refuses_a_ros2_export_saying_what_it_is(exported_ros2, tmp_path, capsys):
    out = tmp_path / "back.h5"
    assert main(["import", "mcap", str(exported_ros2), "--out", str(out)]) != 0
    err = capsys.readouterr().err
    assert "ROS 2 messages (cdr: /tf, /tf_static" in err and "without --profile ros2" in err
    assert not out.exists()
