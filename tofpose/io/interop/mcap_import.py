"""MCAP file -> HDF5 recording (``tofpose import mcap``; docs/interop.md).

Reads with the ``mcap`` library's reader; protobuf messages are decoded by
``mcap-protobuf-support`` from the schema each channel names, JSON ones with ``json``.
A file we exported round-trips exactly: frames bit for bit (the images' bytes), capture
times and reference poses from our JSON channels, the camera and catalog from the
``tofpose`` metadata record. A file from elsewhere (a ROS 2 bag, a Foxglove recording)
imports when it has a 16-bit gray image and a distance image on two ``foxglove.RawImage``
topics (``--gray-topic`` / ``--distance-topic``) and a ``foxglove.CameraCalibration``;
its distance is converted to millimetres from its channel's ``unit`` metadata (metres
when absent, Foxglove's convention for ``32FC1``; ``16UC1`` is millimetres, 0 invalid).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap_protobuf.decoder import DecoderFactory
from tqdm import tqdm

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.io.interop import topics
from tofpose.io.recording import RecordingWriter

GRAY_ENCODINGS: dict[str, np.dtype] = {
    "mono16": np.dtype("<u2"),
    "16UC1": np.dtype("<u2"),
    "mono8": np.dtype("u1"),
    "8UC1": np.dtype("u1"),
}
DISTANCE_ENCODINGS: dict[str, np.dtype] = {"32FC1": np.dtype("<f4"), "16UC1": np.dtype("<u2")}
RAW_IMAGE = "foxglove.RawImage"
CALIBRATION = "foxglove.CameraCalibration"


class McapImportError(ValueError):
    """An MCAP file that cannot become a recording: names the file and what is missing."""


def image_array(msg, encodings: dict[str, np.dtype], what: str, where: str) -> np.ndarray:
    """A decoded ``foxglove.RawImage`` -> (H, W) array of its encoding's dtype."""
    dtype = encodings.get(msg.encoding)
    if dtype is None:
        raise McapImportError(
            f"{where}: {what} image encoding {msg.encoding!r} is not one of {sorted(encodings)}"
        )
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if step < w * dtype.itemsize or len(msg.data) < h * step:
        raise McapImportError(
            f"{where}: {what} image of {w}x{h} has {len(msg.data)} bytes, step {step}"
        )
    rows = np.frombuffer(msg.data, np.uint8, count=h * step).reshape(h, step)
    return rows[:, : w * dtype.itemsize].copy().view(dtype).reshape(h, w)


def distance_mm(msg, unit: str | None, where: str) -> np.ndarray:
    """A distance RawImage in millimetres (float32, NaN invalid)."""
    d = image_array(msg, DISTANCE_ENCODINGS, "distance", where)
    if msg.encoding == "16UC1":  # ROS depth convention: uint16 mm, 0 = no return
        out = d.astype(np.float32)
        out[d == 0] = np.nan
        return out
    if unit == "mm":
        return d.astype(np.float32, copy=False)
    if unit not in (None, "m"):
        raise McapImportError(f"{where}: distance channel unit {unit!r} is not 'mm' or 'm'")
    return (d.astype(np.float64) * 1000.0).astype(np.float32)


def _camera_from_calibration(msg) -> CameraModel:
    K = list(msg.K)
    if len(K) != 9 or K[0] == 0.0:
        raise ValueError("CameraCalibration has no K (uncalibrated camera)")
    dist = list(msg.D)[:5] + [0.0] * max(0, 5 - len(msg.D))
    return CameraModel(
        width=int(msg.width),
        height=int(msg.height),
        fx=K[0],
        fy=K[4],
        cx=K[2],
        cy=K[5],
        dist=tuple(dist),
        name="mcap",
    )


def _pose(payload: dict, where: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        R = np.asarray(payload["R_camera_target"], float).reshape(3, 3)
        t = np.asarray(payload["t_camera_target_mm"], float).reshape(3)
    except (KeyError, ValueError, TypeError) as exc:
        raise McapImportError(f"{where}: malformed pose message ({exc})") from exc
    return R, t


class _Source:
    """An open MCAP file: its summary, metadata and decoded messages in log-time order."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._factory = DecoderFactory()
        try:
            with open(path, "rb") as fh:
                reader = make_reader(fh)
                summary = reader.get_summary()
                self.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except (OSError, McapError, ValueError) as exc:
            raise McapImportError(f"{path}: not a readable MCAP file ({exc})") from exc
        if summary is None or summary.statistics is None:
            raise McapImportError(
                f"{path}: no summary section with statistics (an MCAP file not closed "
                "properly; `mcap recover` repairs it)"
            )
        self.summary = summary
        self.by_topic = {c.topic: c for c in summary.channels.values()}
        cdr = sorted(c.topic for c in summary.channels.values() if c.message_encoding == "cdr")
        if cdr and len(cdr) == len(self.by_topic):
            named = ", ".join(cdr[:4]) + (", ..." if len(cdr) > 4 else "")
            raise McapImportError(
                f"{path}: ROS 2 messages (cdr: {named}); `import mcap` reads Foxglove's "
                "schemas (an `export mcap` without --profile ros2), `import ros2` reads "
                "ROS 2 bags"
            )
        self.counts = {
            summary.channels[cid].topic: n
            for cid, n in summary.statistics.channel_message_counts.items()
        }

    def schema_name(self, topic: str) -> str:
        ch = self.by_topic[topic]
        sc = self.summary.schemas.get(ch.schema_id)
        return sc.name if sc is not None else ""

    def topics_with_schema(self, name: str) -> list[str]:
        return sorted(t for t in self.by_topic if self.schema_name(t) == name)

    @property
    def ours(self) -> bool:
        meta = self.metadata.get(topics.METADATA_NAME, {})
        return meta.get("format") == "tofpose-mcap"

    def messages(self, wanted: list[str]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log_time_ns, decoded) of ``wanted``: in the order written for a file
        we exported (frame order, even where capture times go back), else in log-time
        order. Decoded: the JSON value, or the protobuf message."""
        decoders: dict[int, Callable[[bytes], Any]] = {}
        with open(self.path, "rb") as fh:
            # file order through the non-seeking reader, which streams chunk by chunk (the
            # seeking one queues every chunk before the first message in file order)
            reader = NonSeekingReader(fh) if self.ours else make_reader(fh)
            for schema, channel, message in reader.iter_messages(
                topics=wanted, log_time_order=not self.ours
            ):
                if channel.message_encoding == "json":
                    yield channel.topic, message.log_time, json.loads(message.data)
                    continue
                dec = decoders.get(channel.id)
                if dec is None:
                    dec = self._factory.decoder_for(channel.message_encoding, schema)
                    if dec is None:
                        raise McapImportError(
                            f"{self.path}: {channel.topic} is {channel.message_encoding!r} "
                            f"with schema {schema.name if schema else None!r}: no decoder"
                        )
                    decoders[channel.id] = dec
                yield channel.topic, message.log_time, dec(message.data)

    def first(self, topic: str):
        for _t, _ns, decoded in self.messages([topic]):
            return decoded
        return None


def _pick_topic(src: _Source, requested: str | None, default: str, what: str) -> str:
    raw = src.topics_with_schema(RAW_IMAGE)
    topic = requested or default
    if topic not in src.by_topic:
        raise McapImportError(
            f"{src.path}: no {what} topic {topic!r}; the file's foxglove.RawImage topics: "
            f"{raw or 'none'} (pass --{what}-topic)"
        )
    if src.schema_name(topic) != RAW_IMAGE:
        raise McapImportError(
            f"{src.path}: {topic} has schema {src.schema_name(topic)!r}, not {RAW_IMAGE}"
        )
    return topic


def _camera_and_catalog(src: _Source) -> tuple[CameraModel, Catalog | None]:
    meta = src.metadata.get(topics.METADATA_NAME, {})
    # the recording's own catalog (an export with --catalog estimated with another one)
    text = meta.get("recording_catalog", meta.get("catalog"))
    catalog = Catalog.from_json(text) if text else None
    if meta.get("recording_camera"):
        return CameraModel.from_json(meta["recording_camera"]), catalog
    calib = src.topics_with_schema(CALIBRATION)
    if not calib:
        raise McapImportError(
            f"{src.path}: no camera model (neither a 'tofpose' metadata "
            f"record nor a {CALIBRATION} channel)"
        )
    try:
        return _camera_from_calibration(src.first(calib[0])), catalog
    except ValueError as exc:
        raise McapImportError(f"{src.path}: {calib[0]}: {exc}") from exc


def _stored_topic(src: _Source, topic: str, n: int) -> str:
    """The name ``topic`` has in ``src``: itself, or an older name of it
    (``topics.LEGACY_TOPICS``) when only that one has a message for each of the ``n``
    frames."""
    if src.counts.get(topic, 0) == n:
        return topic
    for old, new in topics.LEGACY_TOPICS.items():
        if new == topic and src.counts.get(old, 0) == n:
            return old
    return topic


def import_mcap(
    path: str | Path,
    out: str | Path,
    *,
    gray_topic: str | None = None,
    distance_topic: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, int]:
    """Write the frames of the MCAP file ``path`` to the recording ``out``.

    A frame is a gray and a distance image with the same log time; ``/tofpose/truth``
    and ``/tofpose/reference`` become ``/truth`` and ``/reference`` when every frame has
    one (a file written before the rename has ``/tofpose/lab_truth``: read as
    ``/tofpose/reference``, ``topics.LEGACY_TOPICS``). Returns {"frames": N}.
    ``McapImportError`` names what is missing or malformed.
    """
    path, out = Path(path), Path(out)
    if out.exists() and not overwrite:
        raise McapImportError(f"{out} exists (pass --force to overwrite it)")
    src = _Source(path)
    gray_t = _pick_topic(src, gray_topic, topics.GRAY, "gray")
    dist_t = _pick_topic(src, distance_topic, topics.DISTANCE, "distance")
    n = src.counts.get(gray_t, 0)
    if n == 0 or src.counts.get(dist_t, 0) != n:
        raise McapImportError(
            f"{path}: {n} gray and {src.counts.get(dist_t, 0)} distance "
            "images: a frame needs one of each"
        )
    camera, catalog = _camera_and_catalog(src)
    unit = src.by_topic[dist_t].metadata.get("unit")
    reference_t = _stored_topic(src, topics.REFERENCE, n)
    extra = [t for t in (topics.FRAME, topics.TRUTH, reference_t) if src.counts.get(t, 0) == n]
    partial = out.with_name(out.name + ".partial")  # renamed when complete
    writer = RecordingWriter(
        partial,
        camera,
        catalog,
        with_truth=topics.TRUTH in extra,
        with_reference=reference_t in extra,
    )
    frames = 0
    try:
        group: dict[str, Any] = {}
        group_ns: int | None = None
        bar = tqdm(total=n, desc="import mcap", unit="frame", disable=not progress, file=sys.stderr)

        def flush(ns: int) -> None:
            """Write the frame of the messages in ``group``, logged at ``ns``."""
            nonlocal frames
            where = f"{path} at log time {ns} ns"
            if gray_t not in group or dist_t not in group:
                missing = gray_t if gray_t not in group else dist_t
                raise McapImportError(f"{where}: no {missing} message for this frame")
            gray = image_array(group[gray_t], GRAY_ENCODINGS, "gray", where).astype(np.uint16)
            dist = distance_mm(group[dist_t], unit, where)
            if gray.shape != (camera.height, camera.width) or dist.shape != gray.shape:
                raise McapImportError(
                    f"{where}: images {gray.shape} / {dist.shape} do not "
                    f"match the camera's {camera.width}x{camera.height}"
                )
            frame = group.get(topics.FRAME)
            time_s = float(frame["time_s"]) if frame is not None else ns * 1e-9
            poses = {}
            for key, topic in (("truth", topics.TRUTH), ("lab", reference_t)):
                if topic in extra:
                    if topic not in group:
                        raise McapImportError(f"{where}: no {topic} message for this frame")
                    poses[key] = _pose(group[topic], where)
            truth, lab = poses.get("truth", (None, None)), poses.get("lab", (None, None))
            writer.append(
                gray,
                dist,
                time_s,
                truth[0],
                truth[1],
                lab_R_camera_target=lab[0],
                lab_t_camera_target_mm=lab[1],
            )
            frames += 1
            bar.update(1)

        for topic, ns, decoded in src.messages([gray_t, dist_t, *extra]):
            if group_ns is not None and ns != group_ns:
                flush(group_ns)
                group = {}
            group_ns = ns
            if topic in group:
                raise McapImportError(f"{path}: two {topic} messages at log time {ns} ns")
            group[topic] = decoded
        if group_ns is not None:  # the last frame, its messages in group
            flush(group_ns)
        bar.close()
    except BaseException:
        writer.close()
        partial.unlink(missing_ok=True)  # no half-written recording left behind
        raise
    writer.close()
    partial.replace(out)
    return {"frames": frames}
