"""ROS 2 bag -> HDF5 recording (``tofpose import ros2``; docs/interop.md, "ROS 2 in").

Reads with ``rosbags`` (``AnyReader``: rosbag2 in MCAP or sqlite3 storage, a bag
directory or a bare ``.mcap`` file; its CDR deserialiser, with the bag's own message
definitions, or ROS 2 Humble's for a bag without them). Three topics: an amplitude / IR
``sensor_msgs/msg/Image`` (``--image``), a depth ``Image`` (``--depth``) and a
``sensor_msgs/msg/CameraInfo`` (``--camera-info``; default: the ``camera_info`` beside the
image topic, image_transport's pairing, else the bag's only one). The defaults are the
topics of ``tofpose export mcap --profile ros2`` (``ros2_topics``), so an export imports
back as it was.

A frame is an amplitude and a depth image with the same header stamp; its ``time_s`` is
that stamp. Images without a partner at their stamp are counted and left out. The depth is
z depth (REP 118) unless ``depth_kind`` says "radial" (our export's
``/tofpose/camera/distance``, which is read as radial by default); it is stored as radial
distance along each pixel's ray (``tofpose.core.depth.radial_from_z``) in mm, NaN where
invalid. The camera: K and D of the first ``CameraInfo`` (``ros2_images``), every device
field from a profile (``camera``; default the TOFcam-660's).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore
from tqdm import tqdm

from tofpose.core.camera import CameraModel
from tofpose.core.depth import radial_from_z
from tofpose.io.interop import ros2_topics
from tofpose.io.interop.ros2_images import (
    Ros2MessageError,
    amplitude_counts,
    camera_from_info,
    depth_mm,
)
from tofpose.io.recording import RecordingWriter

DepthKind = Literal["z", "radial"]


class Ros2ImportError(ValueError):
    """A bag that cannot become a recording: names the bag, the topic and the problem."""


@dataclass(frozen=True)
class Ros2ImportSummary:
    """frames : written; unpaired_image, unpaired_depth : images left out (no partner at
    their stamp); camera : the recording's; lens_fit_max_px : the five-coefficient lens's
    largest pixel error against a ``rational_polynomial`` CameraInfo (0 otherwise);
    max_amplitude_counts : the largest amplitude of any frame (above the camera's
    ``full_scale_counts``: the camera's device fields are not the bag's camera's)."""

    frames: int
    unpaired_image: int
    unpaired_depth: int
    camera: CameraModel
    lens_fit_max_px: float
    max_amplitude_counts: float = 0.0


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _topic_list(reader: AnyReader) -> str:
    seen = sorted({(c.topic, c.msgtype) for c in reader.connections})
    return ", ".join(f"{t} ({m})" for t, m in seen) or "none"


def _connections(reader: AnyReader, path: Path, topic: str, msgtype: str, option: str) -> list:
    """The bag's connections of ``topic``; ``Ros2ImportError`` listing the bag's topics
    when it has none, or naming the type when it is not ``msgtype``."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        raise Ros2ImportError(
            f"{path}: no topic {topic!r} ({option}); the bag's topics: {_topic_list(reader)}"
        )
    wrong = sorted({c.msgtype for c in conns if c.msgtype != msgtype})
    if wrong:
        raise Ros2ImportError(f"{path}: {topic} is {', '.join(wrong)}, not {msgtype}")
    return conns


def _camera_info_topic(reader: AnyReader, path: Path, image_topic: str) -> str:
    """image_transport's ``<namespace>/camera_info`` of ``image_topic``, else the bag's
    only CameraInfo topic; ``Ros2ImportError`` listing them when neither decides."""
    infos = sorted(
        {c.topic for c in reader.connections if c.msgtype == ros2_topics.CAMERA_INFO_TYPE}
    )
    beside = image_topic.rsplit("/", 1)[0] + "/camera_info"
    if beside in infos:
        return beside
    if len(infos) == 1:
        return infos[0]
    raise Ros2ImportError(
        f"{path}: {len(infos)} CameraInfo topics ({', '.join(infos) or 'none'}) and none "
        f"at {beside}: pass --camera-info; the bag's topics: {_topic_list(reader)}"
    )


def _open(path: Path) -> AnyReader:
    if not path.exists():
        raise Ros2ImportError(f"{path}: no such bag (a rosbag2 directory or an .mcap file)")
    reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except (AnyReaderError, OSError, ValueError) as exc:
        raise Ros2ImportError(f"{path}: not a readable ROS 2 bag ({exc})") from exc
    return reader


def import_ros2(
    path: str | Path,
    out: str | Path,
    *,
    image_topic: str = ros2_topics.AMPLITUDE,
    depth_topic: str = ros2_topics.DEPTH,
    camera_info_topic: str | None = None,
    depth_kind: DepthKind | None = None,
    camera: CameraModel | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> Ros2ImportSummary:
    """Write the frames of the ROS 2 bag ``path`` to the recording ``out``.

    Parameters
    ----------
    path : a rosbag2 directory (MCAP or sqlite3 storage) or an ``.mcap`` file.
    out : the recording to write (``.h5``).
    image_topic, depth_topic, camera_info_topic : str, keyword-only
        The amplitude / IR image, the depth image and the CameraInfo (None: beside the
        image, else the only one).
    depth_kind : {"z", "radial"} or None, keyword-only
        What the depth image holds; None: "radial" for our export's distance topic,
        else "z" (REP 118).
    camera : CameraModel or None, keyword-only
        The device fields (full scale, count scale, modulation, range, name) of the
        camera; None: the TOFcam-660's (``CameraModel()``). K and D come from the bag.

    Returns
    -------
    Ros2ImportSummary
        ``Ros2ImportError`` names the bag, the topic, the stamp and the problem.
    """
    path, out = Path(path), Path(out)
    if out.exists() and not overwrite:
        raise Ros2ImportError(f"{out} exists (pass --force to overwrite it)")
    if depth_kind is None:
        depth_kind = "radial" if depth_topic == ros2_topics.DISTANCE else "z"
    if depth_kind not in ("z", "radial"):
        raise Ros2ImportError(f"depth kind {depth_kind!r} is not 'z' or 'radial'")
    if image_topic == depth_topic:
        raise Ros2ImportError(f"--image and --depth are the same topic {image_topic!r}")
    reader = _open(path)
    try:
        image_c = _connections(reader, path, image_topic, ros2_topics.IMAGE_TYPE, "--image")
        depth_c = _connections(reader, path, depth_topic, ros2_topics.IMAGE_TYPE, "--depth")
        info_topic = camera_info_topic or _camera_info_topic(reader, path, image_topic)
        info_c = _connections(
            reader, path, info_topic, ros2_topics.CAMERA_INFO_TYPE, "--camera-info"
        )
        info = next(
            (reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(info_c)), None
        )
        if info is None:
            raise Ros2ImportError(f"{path}: {info_topic} has no messages")
        try:
            cam = camera_from_info(info, camera if camera is not None else CameraModel())
        except Ros2MessageError as exc:
            raise Ros2ImportError(f"{path}: {info_topic}: {exc}") from exc
        frames, unpaired, brightest = _write(
            reader, path, out, (image_c, depth_c), cam.camera, depth_kind, progress
        )
    finally:
        reader.close()
    return Ros2ImportSummary(
        frames=frames,
        unpaired_image=unpaired[0],
        unpaired_depth=unpaired[1],
        camera=cam.camera,
        lens_fit_max_px=cam.lens_fit_max_px,
        max_amplitude_counts=brightest,
    )


def _frame_images(
    image_msg, depth_msg, camera: CameraModel, depth_kind: DepthKind, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """(gray (H, W) uint16, radial distance (H, W) float32 mm) of a frame's two messages;
    ``Ros2ImportError`` naming ``where`` for an unknown encoding or a size that is not
    the camera's."""
    try:
        gray = amplitude_counts(image_msg)
        depth = depth_mm(depth_msg)
    except Ros2MessageError as exc:
        raise Ros2ImportError(f"{where}: {exc}") from exc
    if gray.shape != camera.shape or depth.shape != camera.shape:
        raise Ros2ImportError(
            f"{where}: image {gray.shape[1]} x {gray.shape[0]} and depth {depth.shape[1]} x "
            f"{depth.shape[0]}, the CameraInfo says {camera.width} x {camera.height}: "
            "the images must be the same size as the camera"
        )
    distance = depth if depth_kind == "radial" else radial_from_z(depth, camera)
    return gray, distance


def _write(
    reader: AnyReader,
    path: Path,
    out: Path,
    connections: tuple[list, list],
    camera: CameraModel,
    depth_kind: DepthKind,
    progress: bool,
) -> tuple[int, tuple[int, int], float]:
    """Pair the image and depth messages by stamp and append each pair to ``out``.
    Returns (frames, (unpaired images, unpaired depths), the largest amplitude)."""
    image_c, depth_c = connections
    image_topic = image_c[0].topic
    total = sum(c.msgcount for c in image_c)
    partial = out.with_name(out.name + ".partial")  # renamed when complete
    writer = RecordingWriter(partial, camera)
    pending: tuple[dict[int, object], dict[int, object]] = ({}, {})
    frames = 0
    brightest = 0.0
    try:
        bar = tqdm(
            total=total, desc="import ros2", unit="frame", disable=not progress, file=sys.stderr
        )
        for conn, _log_ns, raw in reader.messages(image_c + depth_c):
            msg = reader.deserialize(raw, conn.msgtype)
            ns = _stamp_ns(msg)
            mine, other = (0, 1) if conn.topic == image_topic else (1, 0)
            partner = pending[other].pop(ns, None)
            if partner is None:
                if ns in pending[mine]:
                    raise Ros2ImportError(f"{path}: two {conn.topic} messages stamped {ns} ns")
                pending[mine][ns] = msg
                continue
            image_msg, depth_msg = (msg, partner) if mine == 0 else (partner, msg)
            where = f"{path} at stamp {ns} ns"
            gray, distance = _frame_images(image_msg, depth_msg, camera, depth_kind, where)
            writer.append(gray, distance, ns * 1e-9)
            brightest = max(brightest, float(gray.max()))
            frames += 1
            bar.update(1)
        bar.close()
        if frames == 0:
            raise Ros2ImportError(
                f"{path}: no {image_c[0].topic} and {depth_c[0].topic} messages with the "
                f"same header stamp ({len(pending[0])} images, {len(pending[1])} depth "
                "images): a frame needs both"
            )
    except BaseException:
        writer.close()
        partial.unlink(missing_ok=True)  # no half-written recording left behind
        raise
    writer.close()
    partial.replace(out)
    return frames, (len(pending[0]), len(pending[1])), brightest
