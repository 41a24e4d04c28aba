"""One set of Foxglove channels (``topics``) on a ``foxglove.Context``, logged per frame.

The MCAP export opens an MCAP writer on the context, the live server a Foxglove
WebSocket server; both log through ``ToFChannels.log_frame``.
"""

from __future__ import annotations

import json

import foxglove
import numpy as np
from foxglove.channels import (
    CameraCalibrationChannel,
    FrameTransformChannel,
    ImageAnnotationsChannel,
    PointCloudChannel,
    PoseInFrameChannel,
    RawImageChannel,
)

from tofpose.core.camera import CameraModel
from tofpose.io.interop import foxglove_messages as msg
from tofpose.io.interop import topics
from tofpose.pipeline import PoseResult


def json_channel(topic: str, schema: dict, context: foxglove.Context) -> foxglove.Channel:
    """A JSON channel whose schema (``jsonschema`` encoding) is named by its ``title``."""
    return foxglove.Channel(
        topic,
        schema=foxglove.Schema(
            name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
        ),
        message_encoding="json",
        context=context,
    )


class ToFChannels:
    """The channels of one camera stream on ``context``, all advertised at construction
    (a live client can subscribe before the first frame).

    camera : the model logged as ``CameraCalibration`` with every frame (so a client that
    joins late, or a player that seeks, has it at once).
    estimate / truth / reference : create the channels of the pipeline's results, of the
    pose the simulator rendered (truth) and of the lab's reference; ``log_frame``
    refuses what has no channel.
    previews : also the images viewers display as they are (``previews``): the gray
    image in 8 bits and the distance colour-mapped.
    """

    def __init__(
        self,
        context: foxglove.Context,
        camera: CameraModel,
        *,
        estimate: bool = True,
        truth: bool = False,
        reference: bool = False,
        previews: bool = True,
        trail: bool = False,
        motion_fields: tuple[str, ...] = (),
    ) -> None:
        self.camera = camera
        self.previews = (
            (
                RawImageChannel(topics.GRAY_PREVIEW, context=context),
                RawImageChannel(topics.DISTANCE_PREVIEW, context=context),
            )
            if previews
            else ()
        )
        self.gray = RawImageChannel(topics.GRAY, context=context)
        self.distance = RawImageChannel(
            topics.DISTANCE, context=context, metadata=topics.DISTANCE_CHANNEL_METADATA
        )
        self.calibration = CameraCalibrationChannel(topics.CALIBRATION, context=context)
        self.frame = json_channel(topics.FRAME, topics.FRAME_SCHEMA, context)
        self.optional: dict[str, object] = {}
        if estimate:
            self.optional.update(
                {
                    topics.ESTIMATE: json_channel(topics.ESTIMATE, topics.ESTIMATE_SCHEMA, context),
                    topics.ANNOTATIONS: ImageAnnotationsChannel(
                        topics.ANNOTATIONS, context=context
                    ),
                    topics.POSE_TRANSFORM: FrameTransformChannel(
                        topics.POSE_TRANSFORM, context=context
                    ),
                    topics.POSE: PoseInFrameChannel(topics.POSE, context=context),
                    topics.REFLECTORS: PointCloudChannel(topics.REFLECTORS, context=context),
                }
            )
            if trail:
                self.optional[topics.TARGET_ORIGIN] = PointCloudChannel(
                    topics.TARGET_ORIGIN, context=context
                )
        self.motion_fields = motion_fields
        if motion_fields:
            self.optional[topics.ENCODERS] = json_channel(
                topics.ENCODERS, topics.encoders_schema(motion_fields), context
            )
            self.optional[topics.SETPOINT] = json_channel(
                topics.SETPOINT, topics.setpoint_schema(motion_fields), context
            )
        for wanted, topic, transform in (
            (truth, topics.TRUTH, topics.TRUTH_TRANSFORM),
            (reference, topics.REFERENCE, topics.REFERENCE_TRANSFORM),
        ):
            if wanted:
                self.optional[topic] = json_channel(topic, topics.POSE_SCHEMA, context)
                self.optional[transform] = FrameTransformChannel(transform, context=context)

    def _channel(self, topic: str):
        ch = self.optional.get(topic)
        if ch is None:
            raise ValueError(f"no {topic} channel: this stream was opened without it")
        return ch

    @property
    def channels(self) -> list:
        return [
            self.gray,
            self.distance,
            self.calibration,
            self.frame,
            *self.previews,
            *self.optional.values(),
        ]

    def has_sinks(self) -> bool:
        """Whether anything (an MCAP writer, a subscribed client) takes any channel."""
        return any(ch.has_sinks() for ch in self.channels)

    @staticmethod
    def _emit(ch, make, log_time_ns: int) -> None:
        """Log ``make()`` on ``ch`` when something takes it (a live client subscribes per
        channel: an unsubscribed channel costs no conversion)."""
        if ch.has_sinks():
            ch.log(make(), log_time=log_time_ns)

    def _log_pose(
        self,
        topic: str,
        transform_topic: str,
        child: str,
        index: int,
        pose: tuple[np.ndarray, np.ndarray],
        ts,
        log_time_ns: int,
    ) -> None:
        R, t_mm = pose
        self._emit(self._channel(topic), lambda: msg.pose_payload(index, R, t_mm), log_time_ns)
        self._emit(
            self._channel(transform_topic),
            lambda: msg.frame_transform(R, t_mm, child, ts),
            log_time_ns,
        )

    def log_frame(
        self,
        index: int,
        gray: np.ndarray,
        distance_mm: np.ndarray,
        time_s: float,
        log_time_ns: int,
        result: PoseResult | None = None,
        truth: tuple[np.ndarray, np.ndarray] | None = None,
        reference: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Log one frame (gray (H, W) uint16, distance (H, W) float32 mm) at
        ``log_time_ns``; with the pipeline's ``result`` its estimate, pose, reflectors
        and overlay; with ``truth`` (the rendered pose) / ``reference`` (the lab's) = (R (3, 3),
        t (3,) mm) those poses."""
        ts = msg.timestamp(log_time_ns)
        emit = self._emit
        emit(self.frame, lambda: msg.frame_payload(index, time_s), log_time_ns)
        emit(self.gray, lambda: msg.gray_image(gray, ts), log_time_ns)
        emit(self.distance, lambda: msg.distance_image(distance_mm, ts), log_time_ns)
        emit(self.calibration, lambda: msg.camera_calibration(self.camera, ts), log_time_ns)
        if self.previews:
            gray_preview, distance_preview = self.previews
            emit(
                gray_preview,
                lambda: msg.gray_preview_image(gray, ts, self.camera.full_scale_counts),
                log_time_ns,
            )
            emit(distance_preview, lambda: msg.distance_preview_image(distance_mm, ts), log_time_ns)
        if result is not None:
            emit(
                self._channel(topics.ESTIMATE),
                lambda: json.dumps(msg.estimate_payload(index, time_s, result), allow_nan=False),
                log_time_ns,
            )
            emit(
                self._channel(topics.ANNOTATIONS),
                lambda: msg.image_annotations(result, ts),
                log_time_ns,
            )
            if result.ok:
                R, t_mm = result.R, result.t_mm
                if R is None or t_mm is None:
                    raise ValueError(f"frame {index}: a result marked ok has no pose (R, t_mm)")
                emit(
                    self._channel(topics.POSE_TRANSFORM),
                    lambda: msg.frame_transform(R, t_mm, topics.TARGET_FRAME_ID, ts),
                    log_time_ns,
                )
                emit(
                    self._channel(topics.POSE),
                    lambda: msg.pose_in_frame(R, t_mm, ts),
                    log_time_ns,
                )
                if topics.TARGET_ORIGIN in self.optional:
                    emit(
                        self.optional[topics.TARGET_ORIGIN],
                        lambda: msg.target_origin_cloud(t_mm, ts),
                        log_time_ns,
                    )
            emit(
                self._channel(topics.REFLECTORS),
                lambda: msg.reflector_cloud(result, ts),
                log_time_ns,
            )
        if truth is not None:
            self._log_pose(
                topics.TRUTH,
                topics.TRUTH_TRANSFORM,
                topics.TRUTH_FRAME_ID,
                index,
                truth,
                ts,
                log_time_ns,
            )
        if reference is not None:
            self._log_pose(
                topics.REFERENCE,
                topics.REFERENCE_TRANSFORM,
                topics.REFERENCE_FRAME_ID,
                index,
                reference,
                ts,
                log_time_ns,
            )

    def log_motion(
        self,
        index: int,
        positions: np.ndarray,
        targets: np.ndarray,
        setpoint_index: int | None,
        log_time_ns: int,
    ) -> None:
        """The turntable at frame ``index``: encoders ``positions`` and set-point
        ``targets`` (A,) deg / mm in the order of ``motion_fields`` (NaN: none), the
        campaign's ``setpoint_index`` (None outside a campaign)."""
        fields = self.motion_fields
        self._emit(
            self._channel(topics.ENCODERS),
            lambda: json.dumps(msg.motion_payload(index, fields, positions), allow_nan=False),
            log_time_ns,
        )
        self._emit(
            self._channel(topics.SETPOINT),
            lambda: json.dumps(
                {**msg.motion_payload(index, fields, targets), "setpoint_index": setpoint_index},
                allow_nan=False,
            ),
            log_time_ns,
        )

    def close(self) -> None:
        for ch in self.channels:
            ch.close()
