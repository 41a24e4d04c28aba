"""Channel names, frame ids and the JSON schemas of our own channels (docs/interop.md).

Units follow Foxglove's 3-D conventions where a well-known schema is used (metres,
quaternions x, y, z, w) and ours (millimetres, R_camera_target row-major) in the JSON
channels, which keep every value exact (Python's float repr round-trips float64).
"""

from __future__ import annotations

GRAY = "/tof/gray"  # foxglove.RawImage mono16: the amplitude image in counts
DISTANCE = "/tof/distance"  # foxglove.RawImage 32FC1: radial distance in MILLIMETRES, NaN invalid
GRAY_PREVIEW = "/tof/gray_preview"  # foxglove.RawImage mono8: gamma 0.5 of the 12-bit counts
DISTANCE_PREVIEW = "/tof/distance_preview"  # foxglove.RawImage rgb8: turbo-coloured distance
CALIBRATION = "/tof/calibration"  # foxglove.CameraCalibration (OpenCV K, plumb_bob D)
ANNOTATIONS = "/tof/annotations"  # foxglove.ImageAnnotations on the gray image
FRAME = "/tofpose/frame"  # JSON: index and exact capture time of each frame
POSE_TRANSFORM = "/tofpose/pose_transform"  # foxglove.FrameTransform camera -> target
POSE = "/tofpose/pose"  # foxglove.PoseInFrame: the estimate in the camera frame
REFLECTORS = "/tofpose/reflectors"  # foxglove.PointCloud: matched reflector points
ESTIMATE = "/tofpose/estimate"  # JSON: ok/reason, covariance, sigmas, timings, matches
TRUTH = "/tofpose/truth"  # JSON: the pose the simulator rendered (a recording's /truth)
TRUTH_TRANSFORM = "/tofpose/truth_transform"  # foxglove.FrameTransform camera -> target_truth
REFERENCE = "/tofpose/reference"  # JSON: the lab's reference (a recording's /reference)
REFERENCE_TRANSFORM = "/tofpose/reference_transform"  # camera -> target_reference
TARGET_ORIGIN = "/tofpose/target_origin"  # foxglove.PointCloud: the estimate's origin (trail)
ENCODERS = "/tofpose/motion/encoders"  # JSON: the turntable's encoders at each frame
SETPOINT = "/tofpose/motion/setpoint"  # JSON: the set-point each frame was measured at

CAMERA_FRAME_ID = "camera"
TARGET_FRAME_ID = "target"
TRUTH_FRAME_ID = "target_truth"
REFERENCE_FRAME_ID = "target_reference"

#: older names of channels, read by the importer as the current ones (files written before
#: "truth" came to mean only the rendered pose called the lab's reference "lab_truth")
LEGACY_TOPICS = {
    "/tofpose/lab_truth": REFERENCE,
    "/tofpose/lab_truth_transform": REFERENCE_TRANSFORM,
}

#: the MCAP metadata record with what no channel carries
METADATA_NAME = "tofpose"

#: MCAP channel metadata of the distance channel: what its float32 values are
DISTANCE_CHANNEL_METADATA = {"unit": "mm", "quantity": "radial distance", "invalid": "NaN"}

_VEC = {"type": "array", "items": {"type": "number"}}


def _vec(n: int, description: str) -> dict:
    return {**_VEC, "minItems": n, "maxItems": n, "description": description}


FRAME_SCHEMA = {
    "title": "tofpose.Frame",
    "type": "object",
    "properties": {
        "index": {"type": "integer", "description": "frame number in the recording"},
        "time_s": {"type": "number", "description": "capture time, s (exact float64)"},
    },
    "required": ["index", "time_s"],
}

POSE_SCHEMA = {
    "title": "tofpose.Pose",
    "type": "object",
    "properties": {
        "index": {"type": "integer"},
        "R_camera_target": _vec(9, "rotation target -> camera, row-major"),
        "t_camera_target_mm": _vec(3, "target origin in the camera frame, mm"),
    },
    "required": ["index", "R_camera_target", "t_camera_target_mm"],
}

_NULLABLE_VEC = {"anyOf": [_VEC, {"type": "null"}]}

ESTIMATE_SCHEMA = {
    "title": "tofpose.Estimate",
    "type": "object",
    "properties": {
        "index": {"type": "integer"},
        "time_s": {"type": "number"},
        "ok": {"type": "boolean"},
        "reason": {"type": "string", "description": "why there is no pose (empty when ok)"},
        "mode": {"type": "string", "enum": ["acquisition", "tracking"]},
        "n_matched": {"type": "integer"},
        "n_candidates": {"type": "integer"},
        "frames_used": {"type": "integer", "description": "frames persistence combined"},
        "R_camera_target": {**_NULLABLE_VEC, "description": "row-major 3x3, or null"},
        "t_camera_target_mm": _NULLABLE_VEC,
        "quaternion_wxyz": _NULLABLE_VEC,
        "euler_deg": {**_NULLABLE_VEC, "description": "pitch, yaw, roll (docs/architecture.md)"},
        "covariance": {
            **_NULLABLE_VEC,
            "description": "6x6 row-major over (rotation vector rad, translation mm)",
        },
        "sigma_mm": {**_NULLABLE_VEC, "description": "1-sigma of x, y, z"},
        "sigma_rotvec_deg": {**_NULLABLE_VEC, "description": "1-sigma of the rotation vector"},
        "residual_mm": {"type": ["number", "null"]},
        "timings_ms": {"type": "object", "additionalProperties": {"type": "number"}},
        "matched": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {
                    "id": {"type": "integer"},
                    "u_px": {"type": "number"},
                    "v_px": {"type": "number"},
                    "distance_mm": {"type": "number"},
                    "residual_mm": {"type": ["number", "null"]},
                    "point_mm": _vec(3, "measured point in the camera frame, mm"),
                },
            },
        },
        "unmatched": {
            "type": "array",
            "items": {
                "type": "array",
                "items": {"type": ["number", "null"]},
                "minItems": 3,
                "maxItems": 3,
                "description": "u_px, v_px, distance_mm",
            },
        },
        "rejected": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {
                    "u_px": {"type": "number"},
                    "v_px": {"type": "number"},
                    "diameter_px": {"type": "number"},
                    "reason": {"type": "string"},
                },
            },
        },
    },
    "required": ["index", "time_s", "ok", "reason", "n_matched"],
}


def motion_schema(title: str, fields: tuple[str, ...], what: str) -> dict:
    """The JSON schema of an encoder (``tofpose.Encoders``) or set-point
    (``tofpose.SetPoint``) message: one number per axis named with its unit
    (``yaw_deg``, ``rail_mm``; null = ``what``)."""
    axes = {f: {"type": ["number", "null"], "description": what} for f in fields}
    properties = {
        "index": {"type": "integer", "description": "frame number in the recording"},
        **axes,
    }
    if title == "tofpose.SetPoint":
        properties["setpoint_index"] = {
            "type": ["integer", "null"],
            "description": "the campaign's set-point number (null: not a campaign)",
        }
    return {
        "title": title,
        "type": "object",
        "properties": properties,
        "required": ["index", *fields],
    }


def encoders_schema(fields: tuple[str, ...]) -> dict:
    return motion_schema(
        "tofpose.Encoders", fields, "axis position read back, deg / mm (null: none)"
    )


def setpoint_schema(fields: tuple[str, ...]) -> dict:
    return motion_schema(
        "tofpose.SetPoint", fields, "commanded position, deg / mm (null: left as is)"
    )
