"""HDF5 recording -> ROS 2 MCAP file (``tofpose export mcap --profile ros2``;
docs/interop.md, "ROS 2").

Channels (``ros2_topics``): message encoding ``cdr``, schema encoding ``ros2msg`` with
each type's complete definition (``ros2_schemas``), MCAP profile ``ros2``; a ROS 2 tool
(``ros2 bag play``, rosbags, Foxglove, PlotJuggler) reads it as a bag. Encoding is
``mcap-ros2-support``'s writer, one frame at a time (memory bounded by its chunk). Log
times and header stamps = the frames' capture times. With a pipeline, each frame's pose
and the relative-state filter's state (``tofpose estimate --filter``'s model) over them.
The ``tofpose`` metadata record is the Foxglove profile's (``mcap_export``), with
``profile`` = ``ros2`` and ``distance_unit`` = ``m``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from mcap_ros2.writer import Writer
from tqdm import tqdm

from tofpose.io.interop import ros2_messages as msg
from tofpose.io.interop import ros2_topics as topics
from tofpose.io.interop import topics as foxglove_topics
from tofpose.io.interop.mcap_export import export_metadata, message_times_ns, pose_at
from tofpose.io.interop.ros2_schemas import definition
from tofpose.io.recording import Recording
from tofpose.lab.motion_models import TwoModelRelativeState
from tofpose.lab.relative_state import RelativeState
from tofpose.pipeline import PosePipeline, PoseResult


class _Ros2Channels:
    """The schemas registered on ``writer`` (one per message type) and its writes by topic."""

    def __init__(self, writer: Writer) -> None:
        self.writer = writer
        self.schemas = {
            name: writer.register_msgdef(name, definition(name))
            for name in sorted(set(topics.TYPES.values()))
        }

    def write(self, topic: str, message: dict, time_ns: int) -> None:
        schema = self.schemas[topics.TYPES[topic]]
        self.writer.write_message(topic, schema, message, log_time=time_ns, publish_time=time_ns)


def _reference_transforms(rec: Recording, i: int, time_ns: int) -> list[dict]:
    """Frame ``i``'s /truth and /reference as transforms from the optical frame."""
    out = []
    for pose, child in (
        (pose_at(rec.truth_R, rec.truth_t_mm, i), topics.TRUTH_FRAME_ID),
        (pose_at(rec.reference_R, rec.reference_t_mm, i), topics.REFERENCE_FRAME_ID),
    ):
        if pose is not None:
            R, t_mm = pose
            out.append(msg.transform(R, t_mm, topics.CAMERA_OPTICAL_FRAME_ID, child, time_ns))
    return out


def _write_estimate(
    ch: _Ros2Channels, index: int, result: PoseResult, time_ns: int, tf: list[dict]
) -> None:
    """A pose (ok ``result``): ``/tofpose/pose`` and its transform appended to ``tf``."""
    R, t_mm, cov = result.R, result.t_mm, result.covariance
    if R is None or t_mm is None or cov is None:
        raise ValueError(f"frame {index}: a result marked ok has no pose or covariance")
    ch.write(topics.POSE, msg.pose_with_covariance(R, t_mm, cov, time_ns), time_ns)
    tf.append(
        msg.transform(R, t_mm, topics.CAMERA_OPTICAL_FRAME_ID, topics.TARGET_FRAME_ID, time_ns)
    )


def _write_state(ch: _Ros2Channels, s: RelativeState, time_ns: int) -> None:
    """The filter's pose (covariance block [0:6, 0:6]) and twist ([6:12, 6:12])."""
    ch.write(
        topics.STATE_POSE,
        msg.pose_with_covariance(s.R, s.t_mm, s.covariance[:6, :6], time_ns),
        time_ns,
    )
    rate_rad_s = np.radians(s.angular_rate_deg_s)
    twist = msg.twist_with_covariance(
        rate_rad_s, s.velocity_mm_s, s.covariance[6:12, 6:12], time_ns
    )
    ch.write(topics.STATE_TWIST, twist, time_ns)


def export_ros2_mcap(
    rec: Recording,
    out: str | Path,
    pipeline: PosePipeline | None = None,
    *,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, int]:
    """Write ``rec`` to ``out`` as a ROS 2 MCAP; with a ``pipeline``, each frame's pose
    and the relative state too.

    Returns {"frames": N, "ok": frames with a pose}. ValueError when ``out`` exists
    (without ``overwrite``) or for a capture time MCAP cannot hold (negative)."""
    out = Path(out)
    if out.exists() and not overwrite:
        raise ValueError(f"{out} exists (pass --force to overwrite it)")
    times_ns = message_times_ns(rec)  # the wall clock when the recording has it
    metadata = {
        **export_metadata(rec, pipeline),
        "profile": topics.MCAP_PROFILE,
        "distance_unit": "m",
    }
    rel = TwoModelRelativeState() if pipeline is not None else None  # as estimate --filter
    n_ok = 0
    partial = out.with_name(out.name + ".partial")  # renamed when complete
    done = False
    try:
        with open(partial, "wb") as fh:
            writer = Writer(fh)
            writer.add_metadata(foxglove_topics.METADATA_NAME, metadata)
            ch = _Ros2Channels(writer)
            for i in tqdm(
                range(rec.n_frames),
                desc="export mcap (ros2)",
                unit="frame",
                disable=not progress,
                file=sys.stderr,
            ):
                gray, dist, time_s = rec.frame(i)
                t_ns = times_ns[i]
                if i == 0:
                    static = msg.tf_message([msg.camera_link_transform(t_ns)])
                    ch.write(topics.TF_STATIC, static, t_ns)
                ch.write(topics.CAMERA_INFO, msg.camera_info(rec.camera, t_ns), t_ns)
                ch.write(topics.AMPLITUDE, msg.amplitude_image(gray, t_ns), t_ns)
                ch.write(topics.DISTANCE, msg.distance_image(dist, t_ns), t_ns)
                ch.write(topics.DEPTH, msg.depth_image(dist, rec.camera, t_ns), t_ns)
                tf: list[dict] = []
                if pipeline is not None and rel is not None:
                    r = pipeline.process(gray, dist, time_s)
                    if r.ok:
                        n_ok += 1
                        _write_estimate(ch, i, r, t_ns, tf)
                    pose = (r.R, r.t_mm, r.covariance) if r.ok else (None, None, None)
                    state = rel.step(float(time_s), *pose)
                    if state is not None:
                        _write_state(ch, state, t_ns)
                tf += _reference_transforms(rec, i, t_ns)
                if tf:
                    ch.write(topics.TF, msg.tf_message(tf), t_ns)
            writer.finish()
        done = True
    finally:
        if done:
            partial.replace(out)
        else:
            partial.unlink(missing_ok=True)
    return {"frames": rec.n_frames, "ok": n_ok}
