"""Our frames, poses and overlays as Foxglove messages (``foxglove.messages``) and JSON.

Pure conversions, no I/O. Foxglove's 3-D messages are in metres with quaternions
(x, y, z, w); our JSON payloads keep millimetres and the exact float64 values.
Image coordinates: ours put pixel centres at integer (u, v); Foxglove's annotations put
the origin at the top-left corner of the top-left pixel, so they are shifted by 0.5 px.
"""

from __future__ import annotations

import math

import numpy as np
from foxglove import messages as fm

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import quaternion_wxyz_from_rotation
from tofpose.io.interop import topics
from tofpose.io.interop.previews import FULL_SCALE_COUNTS, distance_to_rgb, gray_to_u8
from tofpose.pipeline import PoseResult

MATCHED_RGBA = (0.31, 0.86, 0.31, 1.0)
UNMATCHED_RGBA = (1.0, 0.24, 0.24, 1.0)
REJECTED_RGBA = (1.0, 0.65, 0.1, 0.9)
LABEL_RGBA = (1.0, 1.0, 1.0, 1.0)
LABEL_BACKGROUND_RGBA = (0.0, 0.0, 0.0, 0.5)


def timestamp(time_ns: int) -> fm.Timestamp:
    """A Foxglove timestamp from integer nanoseconds (>= 0)."""
    sec, nsec = divmod(int(time_ns), 1_000_000_000)
    return fm.Timestamp(sec=sec, nsec=nsec)


def time_ns_from_seconds(time_s: float) -> int:
    """Capture time (s, float64) -> MCAP log time (integer ns); ValueError if negative."""
    if not math.isfinite(time_s) or time_s < 0:
        raise ValueError(f"capture time {time_s!r} s cannot be an MCAP log time (needs >= 0)")
    return int(round(time_s * 1e9))


def _raw_image(image: np.ndarray, dtype: str, encoding: str, ts: fm.Timestamp) -> fm.RawImage:
    """(H, W) array as a RawImage of unpadded little-endian rows."""
    a = np.ascontiguousarray(image, dtype=dtype)
    h, w = a.shape
    return fm.RawImage(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        width=w,
        height=h,
        encoding=encoding,
        step=a.itemsize * w,
        data=a.tobytes(),
    )


def gray_image(gray: np.ndarray, ts: fm.Timestamp) -> fm.RawImage:
    """(H, W) uint16 counts -> RawImage ``mono16`` (little-endian rows, step = 2 W)."""
    return _raw_image(gray, "<u2", "mono16", ts)


def distance_image(distance_mm: np.ndarray, ts: fm.Timestamp) -> fm.RawImage:
    """(H, W) float32 radial distance, mm, NaN invalid -> RawImage ``32FC1`` with the
    values unchanged (mm, not Foxglove's usual metres: a conversion to metres in float32
    would not round-trip bit-exactly; the channel's metadata says ``unit: mm``)."""
    return _raw_image(distance_mm, "<f4", "32FC1", ts)


def gray_preview_image(
    gray: np.ndarray, ts: fm.Timestamp, full_scale_counts: float = FULL_SCALE_COUNTS
) -> fm.RawImage:
    """(H, W) uint16 counts -> RawImage ``mono8`` as the dashboard shows it
    (``previews.gray_to_u8`` at the camera's ``full_scale_counts``): a 12-bit image in
    ``mono16`` looks black in a viewer."""
    return _raw_image(gray_to_u8(gray, full_scale_counts), "u1", "mono8", ts)


def distance_preview_image(distance_mm: np.ndarray, ts: fm.Timestamp) -> fm.RawImage:
    """(H, W) distance, mm -> RawImage ``rgb8``, turbo over the 2nd-98th percentile,
    invalid black (``previews.distance_to_rgb``, the dashboard's view)."""
    rgb = distance_to_rgb(distance_mm)
    h, w, _ = rgb.shape
    return fm.RawImage(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        width=w,
        height=h,
        encoding="rgb8",
        step=3 * w,
        data=rgb.tobytes(),
    )


def camera_calibration(camera: CameraModel, ts: fm.Timestamp) -> fm.CameraCalibration:
    """The pinhole model and its OpenCV distortion (k1, k2, p1, p2, k3 = ``plumb_bob``)."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    return fm.CameraCalibration(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        width=camera.width,
        height=camera.height,
        distortion_model="plumb_bob",
        D=[float(v) for v in np.asarray(camera.dist, float)],
        K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def _quaternion(R: np.ndarray) -> fm.Quaternion:
    w, x, y, z = (float(v) for v in quaternion_wxyz_from_rotation(np.asarray(R, float)))
    return fm.Quaternion(x=x, y=y, z=z, w=w)


def _vector_m(t_mm: np.ndarray) -> fm.Vector3:
    x, y, z = (float(v) / 1000.0 for v in t_mm)
    return fm.Vector3(x=x, y=y, z=z)


def frame_transform(
    R: np.ndarray, t_mm: np.ndarray, child_frame_id: str, ts: fm.Timestamp
) -> fm.FrameTransform:
    """T_camera_child (R (3, 3), t (3,) mm) as a FrameTransform camera -> child, metres."""
    return fm.FrameTransform(
        timestamp=ts,
        parent_frame_id=topics.CAMERA_FRAME_ID,
        child_frame_id=child_frame_id,
        translation=_vector_m(t_mm),
        rotation=_quaternion(R),
    )


def pose_in_frame(R: np.ndarray, t_mm: np.ndarray, ts: fm.Timestamp) -> fm.PoseInFrame:
    """The target's pose in the camera frame, metres."""
    p = _vector_m(t_mm)
    return fm.PoseInFrame(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        pose=fm.Pose(position=p, orientation=_quaternion(R)),
    )


#: PointCloud layout of the reflectors: x, y, z metres (float32), catalog id (uint32),
#: residual mm (float32); 20 bytes a point
_CLOUD_FIELDS = (
    ("x", 0, fm.PackedElementFieldNumericType.Float32),
    ("y", 4, fm.PackedElementFieldNumericType.Float32),
    ("z", 8, fm.PackedElementFieldNumericType.Float32),
    ("id", 12, fm.PackedElementFieldNumericType.Uint32),
    ("residual_mm", 16, fm.PackedElementFieldNumericType.Float32),
)
CLOUD_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("id", "<u4"), ("residual_mm", "<f4")]
)


def reflector_cloud(result: PoseResult, ts: fm.Timestamp) -> fm.PointCloud:
    """The matched reflectors' measured points (camera frame, metres) with their ids."""
    pts = np.zeros(len(result.matched), CLOUD_DTYPE)
    for k, m in enumerate(result.matched):
        x, y, z = (float(v) / 1000.0 for v in m.point_mm)
        pts[k] = (x, y, z, m.catalog_id, m.residual_mm)
    return fm.PointCloud(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        pose=fm.Pose(
            position=fm.Vector3(x=0.0, y=0.0, z=0.0),
            orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        point_stride=CLOUD_DTYPE.itemsize,
        fields=[fm.PackedElementField(name=n, offset=o, type=t) for n, o, t in _CLOUD_FIELDS],
        data=pts.tobytes(),
    )


_ORIGIN_FIELDS = _CLOUD_FIELDS[:3]
ORIGIN_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])


def target_origin_cloud(t_mm: np.ndarray, ts: fm.Timestamp) -> fm.PointCloud:
    """One point: the estimated target origin ``t_camera_target`` (3,) mm, in the camera
    frame in metres. Shown with its history (Foxglove's decay time, Rerun's visible
    time range), the points are the pose's trail."""
    pts = np.zeros(1, ORIGIN_DTYPE)
    pts[0] = tuple(float(v) / 1000.0 for v in t_mm)
    return fm.PointCloud(
        timestamp=ts,
        frame_id=topics.CAMERA_FRAME_ID,
        pose=fm.Pose(
            position=fm.Vector3(x=0.0, y=0.0, z=0.0),
            orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        point_stride=ORIGIN_DTYPE.itemsize,
        fields=[fm.PackedElementField(name=n, offset=o, type=t) for n, o, t in _ORIGIN_FIELDS],
        data=pts.tobytes(),
    )


def _color(rgba: tuple[float, float, float, float]) -> fm.Color:
    r, g, b, a = rgba
    return fm.Color(r=r, g=g, b=b, a=a)


def _point(u_px: float, v_px: float) -> fm.Point2:
    return fm.Point2(x=float(u_px) + 0.5, y=float(v_px) + 0.5)


def image_annotations(result: PoseResult, ts: fm.Timestamp) -> fm.ImageAnnotations:
    """The dashboard's overlay: matched blobs (green circle and catalog id), unmatched
    candidates (red circle), blobs a gate rejected (orange circle and the gate's name)."""
    circles, texts = [], []
    for m in result.matched:
        d_px = 2.0 * max(math.sqrt(m.area_px / math.pi), 1.0) + 2.0
        x, y = float(m.centroid_uv[0]) + 0.5, float(m.centroid_uv[1]) + 0.5
        circles.append(
            fm.CircleAnnotation(
                timestamp=ts,
                position=fm.Point2(x=x, y=y),
                diameter=d_px,
                thickness=1.0,
                fill_color=_color((0.0, 0.0, 0.0, 0.0)),
                outline_color=_color(MATCHED_RGBA),
            )
        )
        texts.append(
            fm.TextAnnotation(
                timestamp=ts,
                position=fm.Point2(x=x + d_px / 2 + 1.0, y=y - d_px / 2),
                text=str(m.catalog_id),
                font_size=9.0,
                text_color=_color(LABEL_RGBA),
                background_color=_color(LABEL_BACKGROUND_RGBA),
            )
        )
    for u, v, _d in result.unmatched:
        circles.append(
            fm.CircleAnnotation(
                timestamp=ts,
                position=_point(u, v),
                diameter=6.0,
                thickness=1.0,
                fill_color=_color((0.0, 0.0, 0.0, 0.0)),
                outline_color=_color(UNMATCHED_RGBA),
            )
        )
    for rb in result.rejected:
        x, y = float(rb.u_px) + 0.5, float(rb.v_px) + 0.5
        d_px = max(float(rb.diameter_px), 2.0) + 2.0
        circles.append(
            fm.CircleAnnotation(
                timestamp=ts,
                position=fm.Point2(x=x, y=y),
                diameter=d_px,
                thickness=1.0,
                fill_color=_color((0.0, 0.0, 0.0, 0.0)),
                outline_color=_color(REJECTED_RGBA),
            )
        )
        texts.append(
            fm.TextAnnotation(
                timestamp=ts,
                position=fm.Point2(x=x + d_px / 2 + 1.0, y=y + d_px / 2),
                text=rb.reason,
                font_size=7.0,
                text_color=_color(REJECTED_RGBA),
                background_color=_color(LABEL_BACKGROUND_RGBA),
            )
        )
    return fm.ImageAnnotations(circles=circles, points=[], texts=texts)


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _floats(a) -> list[float] | None:
    return None if a is None else [float(v) for v in np.asarray(a, float).ravel()]


def frame_payload(index: int, time_s: float) -> dict:
    """``topics.FRAME_SCHEMA``."""
    return {"index": int(index), "time_s": float(time_s)}


def pose_payload(index: int, R: np.ndarray, t_mm: np.ndarray) -> dict:
    """``topics.POSE_SCHEMA``: a reference pose, exact."""
    return {"index": int(index), "R_camera_target": _floats(R), "t_camera_target_mm": _floats(t_mm)}


def estimate_payload(index: int, time_s: float, result: PoseResult) -> dict:
    """``topics.ESTIMATE_SCHEMA``: everything a pose claims that no Foxglove schema
    carries (NaN becomes null: JSON has no NaN)."""
    cov = result.covariance if result.ok else None
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if cov is not None else None
    return {
        "index": int(index),
        "time_s": float(time_s),
        "ok": bool(result.ok),
        "reason": result.reason,
        "mode": result.mode,
        "n_matched": result.n_matched,
        "n_candidates": int(result.n_candidates),
        "frames_used": int(result.frames_used),
        "R_camera_target": _floats(result.R) if result.ok else None,
        "t_camera_target_mm": _floats(result.t_mm) if result.ok else None,
        "quaternion_wxyz": _floats(result.quaternion_wxyz) if result.ok else None,
        "euler_deg": _floats(result.euler_deg) if result.ok else None,
        "covariance": _floats(cov),
        "sigma_mm": None if sd is None else _floats(sd[3:]),
        "sigma_rotvec_deg": None if sd is None else _floats(np.degrees(sd[:3])),
        "residual_mm": _finite(result.residual_mm),
        "timings_ms": {k: float(v) for k, v in result.timings_ms.items()},
        "matched": [
            {
                "id": int(m.catalog_id),
                "u_px": float(m.centroid_uv[0]),
                "v_px": float(m.centroid_uv[1]),
                "distance_mm": float(m.distance_mm),
                "residual_mm": _finite(m.residual_mm),
                "point_mm": _floats(m.point_mm),
            }
            for m in result.matched
        ],
        "unmatched": [[float(u), float(v), _finite(d)] for u, v, d in result.unmatched],
        "rejected": [
            {
                "u_px": float(r.u_px),
                "v_px": float(r.v_px),
                "diameter_px": float(r.diameter_px),
                "reason": r.reason,
            }
            for r in result.rejected
        ],
    }


def motion_payload(index: int, fields: tuple[str, ...], values: np.ndarray) -> dict:
    """``topics.encoders_schema`` / ``setpoint_schema``: frame ``index`` and one value
    per axis field (values (A,) deg / mm; NaN -> null)."""
    return {"index": int(index), **{f: _finite(v) for f, v in zip(fields, values, strict=True)}}
