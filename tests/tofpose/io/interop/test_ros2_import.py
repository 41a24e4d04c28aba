"""``tofpose import ros2``: bags written by ``rosbags`` (a ROS 2 writer that shares no code
with the importer's conversions) from a rendered recording, in MCAP and sqlite3 storage,
import to the frames they were written from and give the same poses; our own ROS 2 export
imports back; bad bags get errors that name the problem."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from tofpose.cli import main
from tofpose.core.camera import CameraModel
from tofpose.io.interop.ros2_import import Ros2ImportError, import_ros2
from tofpose.io.recording import open_recording
from tofpose.pipeline import PosePipeline

TYPES = get_typestore(Stores.ROS2_HUMBLE)
Image = TYPES.types["sensor_msgs/msg/Image"]
CameraInfo = TYPES.types["sensor_msgs/msg/CameraInfo"]
Header = TYPES.types["std_msgs/msg/Header"]
Time = TYPES.types["builtin_interfaces/msg/Time"]
RegionOfInterest = TYPES.types["sensor_msgs/msg/RegionOfInterest"]
IMAGE, DEPTH, INFO = "/tof/ir/image_raw", "/tof/depth/image_raw", "/tof/ir/camera_info"
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


def header(ns: int) -> Header:
    return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="tof_optical")


def image(a: np.ndarray, encoding: str, ns: int, *, big_endian: bool = False) -> Image:
    a = np.ascontiguousarray(a, a.dtype.newbyteorder(">" if big_endian else "<"))
    h, w = a.shape
    data = np.frombuffer(a.tobytes(), np.uint8)
    return Image(header(ns), h, w, encoding, int(big_endian), w * a.itemsize, data)


def camera_info(cam: CameraModel, ns: int, *, model: str = "plumb_bob", d=None) -> CameraInfo:
    K = np.array([cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1], float)
    P = np.array([cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0], float)
    return CameraInfo(
        header(ns),
        cam.height,
        cam.width,
        model,
        np.asarray(cam.dist if d is None else d, float),
        K,
        np.eye(3).ravel(),
        P,
        0,
        0,
        RegionOfInterest(0, 0, 0, 0, False),
    )


def write_bag(path: Path, messages: list[tuple[str, int, object]], storage: str = "mcap") -> Path:
    """A rosbag2 bag at ``path`` of (topic, log time ns, message), written by rosbags."""
    with Writer(path, version=9, storage_plugin=STORAGES[storage]) as w:
        conns = {}
        for topic, ns, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msg.__msgtype__, typestore=TYPES)
            w.write(conns[topic], ns, TYPES.serialize_cdr(msg, msg.__msgtype__))
    return path


def ray_z(cam: CameraModel) -> np.ndarray:
    """e_z of each pixel's unit ray (H, W), from OpenCV's undistortion."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(float)
    uv = np.column_stack((u.ravel(), v.ravel())).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(uv, cam.K, cam.dist_array).reshape(cam.height, cam.width, 2)
    return 1.0 / np.sqrt(1.0 + (xy**2).sum(axis=2))


def frames_as_messages(rec_path: Path, *, depth_encoding: str = "32FC1", big_endian=False):
    """The recording's frames as a lab's camera driver would publish them: amplitude
    mono16, z depth (REP 118: 32FC1 m with NaN, or 16UC1 mm with 0), a CameraInfo."""
    out = []
    with open_recording(rec_path) as rec:
        ez = ray_z(rec.camera)
        for i in range(rec.n_frames):
            gray, rho, t = rec.frame(i)
            ns = round(t * 1e9)
            z_mm = rho.astype(float) * ez
            if depth_encoding == "32FC1":
                depth = (z_mm / 1000.0).astype(np.float32)
            else:
                depth = np.where(np.isnan(z_mm), 0, np.rint(z_mm)).astype(np.uint16)
            out.append((INFO, ns, camera_info(rec.camera, ns)))
            out.append((DEPTH, ns, image(depth, depth_encoding, ns, big_endian=big_endian)))
            out.append((IMAGE, ns, image(gray, "mono16", ns, big_endian=big_endian)))
    return out


def poses(rec_path: Path, catalog) -> list:
    with open_recording(rec_path) as rec:
        pipe = PosePipeline(rec.camera, catalog)
        return [pipe.process(*rec.frame(i)) for i in range(rec.n_frames)]


@pytest.fixture(scope="module")
def source(recording):
    """The rendered recording: (its frames, its catalog, its poses)."""
    with open_recording(recording) as rec:
        frames = [rec.frame(i) for i in range(rec.n_frames)]
        catalog, camera = rec.catalog, rec.camera
    return frames, catalog, camera, poses(recording, catalog)


def imported_via_cli(bag: Path, out: Path, *extra: str) -> Path:
    args = ["import", "ros2", str(bag), "--out", str(out), "--image", IMAGE, "--depth", DEPTH]
    assert main([*args, *extra]) == 0
    return out


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_rosbags_bag_round_trips_to_the_same_poses(recording, source, tmp_path, storage):
    frames, catalog, camera, truth_results = source
    bag = write_bag(tmp_path / "bag", frames_as_messages(recording), storage)
    out = imported_via_cli(bag, tmp_path / "rec.h5")
    with open_recording(out) as rec:
        assert rec.camera == camera
        assert rec.n_frames == len(frames)
        for i, (gray, rho, t) in enumerate(frames):
            g, d, time_s = rec.frame(i)
            np.testing.assert_array_equal(g, gray)
            np.testing.assert_array_equal(np.isnan(d), np.isnan(rho))
            assert_allclose(d, rho, rtol=2e-7, atol=0, equal_nan=True)
            assert time_s == pytest.approx(t, abs=1e-9)
    results = poses(out, catalog)
    assert [r.ok for r in results] == [r.ok for r in truth_results]
    assert sum(r.ok for r in results) >= 5
    for got, want in zip(results, truth_results, strict=True):
        if want.ok:
            # the float32 round trip moves ranges by up to 2e-7 of themselves (0.4 um at
            # 2 m): over the markers' ~100 mm baselines up to ~4e-6 rad of attitude
            assert_allclose(got.t_mm, want.t_mm, atol=0.01)
            assert_allclose(got.R, want.R, atol=1e-5)


def test_big_endian_16uc1_depth_in_mm(recording, source, tmp_path):
    """16UC1 depth (z in whole mm, 0 = none) and big-endian rows read as ROS states."""
    frames, _, camera, _ = source
    msgs = frames_as_messages(recording, depth_encoding="16UC1", big_endian=True)
    out = imported_via_cli(write_bag(tmp_path / "bag", msgs), tmp_path / "rec.h5")
    ez = ray_z(camera)
    with open_recording(out) as rec:
        for i, (gray, rho, _) in enumerate(frames):
            g, d, _ = rec.frame(i)
            np.testing.assert_array_equal(g, gray)
            z_mm = np.rint(rho.astype(float) * ez)
            np.testing.assert_array_equal(np.isnan(d), np.isnan(rho) | (z_mm == 0))
            assert_allclose(d, z_mm / ez, rtol=1e-6, equal_nan=True)


def test_our_ros2_export_imports_back(recording, source, tmp_path):
    frames, _, camera, _ = source
    exported = tmp_path / "rec.ros2.mcap"
    args = ["export", "mcap", str(recording), "--out", str(exported), "--profile", "ros2"]
    assert main([*args, "--no-estimate"]) == 0
    for depth in ([], ["--depth", "/tofpose/camera/distance"]):  # z (default), radial
        out = tmp_path / f"back{len(depth)}.h5"
        assert main(["import", "ros2", str(exported), "--out", str(out), *depth]) == 0
        with open_recording(out) as rec:
            assert rec.camera == camera
            for i, (gray, rho, t) in enumerate(frames):
                g, d, time_s = rec.frame(i)
                np.testing.assert_array_equal(g, gray)
                assert_allclose(d, rho, rtol=2e-7, atol=0, equal_nan=True)
                assert time_s == pytest.approx(t, abs=1e-9)


def test_camera_profile_gives_the_device_fields(recording, tmp_path):
    bag = write_bag(tmp_path / "bag", frames_as_messages(recording)[:3])
    out = imported_via_cli(bag, tmp_path / "rec.h5", "--camera", "azure-kinect-nfov")
    with open_recording(out) as rec:
        assert rec.camera.full_scale_counts == 65535.0 and rec.camera.count_scale == 16.0
        assert (rec.camera.width, rec.camera.fx) == (320, 325.0)  # the bag's K, size


# --- bad input: each error names the problem -------------------------------------------

CAM = CameraModel(width=8, height=6, fx=10.0, fy=10.0, cx=3.5, cy=2.5)
NS = 1_500_000_000


def tiny(*, image_enc="mono16", depth_enc="16UC1", depth_shape=(6, 8), info=None, depth_ns=NS):
    """A one-frame 8 x 6 bag's messages, with one thing changed."""
    return [
        (INFO, NS, info or camera_info(CAM, NS)),
        (IMAGE, NS, image(np.full((6, 8), 100, np.uint16), image_enc, NS)),
        (DEPTH, depth_ns, image(np.full(depth_shape, 1000, np.uint16), depth_enc, depth_ns)),
    ]


BAD = {
    "missing-topic": (
        tiny(),
        {"depth_topic": "/camera/depth"},
        r"no topic '/camera/depth' \(--depth\); the bag's topics: /tof/depth/image_raw "
        r"\(sensor_msgs/msg/Image\), /tof/ir/camera_info \(sensor_msgs/msg/CameraInfo\), "
        r"/tof/ir/image_raw \(sensor_msgs/msg/Image\)",
    ),
    "mismatched-sizes": (
        tiny(depth_shape=(5, 8)),
        {},
        r"image 8 x 6 and depth 8 x 5, the CameraInfo says 8 x 6",
    ),
    "unknown-image-encoding": (
        tiny(image_enc="bgr8"),
        {},
        r"amplitude image encoding 'bgr8' is not one of mono16",
    ),
    "unknown-depth-encoding": (
        tiny(depth_enc="16SC1"),
        {},
        r"depth image encoding '16SC1' is not one of 16UC1, 32FC1",
    ),
    "wrong-type": (
        tiny(),
        {"depth_topic": INFO},
        r"/tof/ir/camera_info is sensor_msgs/msg/CameraInfo, not sensor_msgs/msg/Image",
    ),
    "unknown-distortion-model": (
        tiny(info=camera_info(CAM, NS, model="equidistant", d=[0.1, 0, 0, 0])),
        {},
        r"distortion model 'equidistant' is not one of plumb_bob, rational_polynomial",
    ),
    "no-pair": (  # the depth image stamped 1 ns after the amplitude image
        tiny(depth_ns=NS + 1),
        {},
        r"no /tof/ir/image_raw and /tof/depth/image_raw messages with the same header stamp",
    ),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_bag_is_named(tmp_path, case):
    messages, options, message = BAD[case]
    bag = write_bag(tmp_path / "bag", messages)
    out = tmp_path / "out.h5"
    kwargs = {"image_topic": IMAGE, "depth_topic": DEPTH, **options}
    with pytest.raises(Ros2ImportError, match=message) as info:
        import_ros2(bag, out, progress=False, **kwargs)
    assert str(bag) in str(info.value)
    assert not out.exists() and not out.with_name("out.h5.partial").exists()


def test_cli_prints_the_error(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", tiny())
    args = ["import", "ros2", str(bag), "--out", str(tmp_path / "o.h5"), "--image", "/nope"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "no topic '/nope' (--image)" in err and "/tof/ir/image_raw" in err


def test_not_a_bag_is_named(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_text("not a bag")
    with pytest.raises(Ros2ImportError, match="not a readable ROS 2 bag"):
        import_ros2(junk, tmp_path / "o.h5", progress=False)
    with pytest.raises(Ros2ImportError, match="no such bag"):
        import_ros2(tmp_path / "absent", tmp_path / "o.h5", progress=False)


def test_amplitudes_above_the_cameras_full_scale_are_named_in_a_warning(tmp_path, capsys):
    """A 16-bit device's bag imported without --camera: the TOFcam-660's 4095 counts
    would call every brighter pixel saturated, so the CLI says so and how to fix it; with
    the device's profile there is nothing to say."""
    bright = tiny()
    bright[1] = (IMAGE, NS, image(np.full((6, 8), 9000, np.uint16), "mono16", NS))
    bag = write_bag(tmp_path / "bag", bright)
    topics = ["--image", IMAGE, "--depth", DEPTH]
    assert main(["import", "ros2", str(bag), "--out", str(tmp_path / "a.h5"), *topics]) == 0
    out = capsys.readouterr().out
    assert "amplitudes up to 9000 counts" in out and "no --camera given" in out
    args = ["import", "ros2", str(bag), "--out", str(tmp_path / "b.h5"), *topics]
    assert main([*args, "--camera", "azure-kinect-nfov"]) == 0
    assert "warning" not in capsys.readouterr().out
