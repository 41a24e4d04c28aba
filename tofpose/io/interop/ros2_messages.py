"""Our frames, poses and relative state as ROS 2 messages (docs/interop.md, "ROS 2").

Pure conversions, no I/O: each function returns the message as the nested dict of its
fields that ``mcap-ros2-support``'s writer encodes to CDR against the schemas of
``ros2_schemas``. ROS units: metres, radians, quaternions (x, y, z, w); frame ids and
topics from ``ros2_topics``; covariances by ``ros2_covariance``.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import quaternion_wxyz_from_rotation
from tofpose.io.interop import ros2_topics as topics
from tofpose.io.interop.ros2_covariance import ros_covariance_row_major

#: R_camera_link_camera_optical (REP 103): the optical frame's x (right), y (down) and
#: z (forward) axes as columns in the body frame (x forward, y left, z up)
R_LINK_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def header(time_ns: int, frame_id: str) -> dict:
    """``std_msgs/msg/Header`` stamped ``time_ns`` (integer ns >= 0)."""
    sec, nanosec = divmod(int(time_ns), 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}


def _image(a: np.ndarray, encoding: str, time_ns: int) -> dict:
    """(H, W) array of little-endian pixels -> ``sensor_msgs/msg/Image``, unpadded rows."""
    h, w = a.shape
    return {
        "header": header(time_ns, topics.CAMERA_OPTICAL_FRAME_ID),
        "height": h,
        "width": w,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": a.itemsize * w,
        "data": a.tobytes(),
    }


def amplitude_image(gray: np.ndarray, time_ns: int) -> dict:
    """(H, W) uint16 counts -> ``Image`` ``mono16`` (step = 2 W), the values unchanged."""
    return _image(np.ascontiguousarray(gray, dtype="<u2"), "mono16", time_ns)


def distance_m(distance_mm: np.ndarray) -> np.ndarray:
    """(H, W) radial distance, mm -> (H, W) float32 m (in float64, then rounded once to
    float32), NaN kept."""
    return (np.asarray(distance_mm, dtype=np.float64) / 1000.0).astype("<f4")


def depth_m(distance_mm: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(H, W) radial distance, mm -> (H, W) float32 z depth, m (REP 118's depth image):
    rho * e_z with e each pixel centre's unit bearing (``CameraModel.pixel_bearings``,
    lens distortion included), NaN kept. ValueError when the image is not the camera's
    size."""
    d = np.asarray(distance_mm, dtype=np.float64)
    if d.shape != camera.shape:
        raise ValueError(f"distance image is {d.shape}, the camera's is {camera.shape}")
    return (d * camera.pixel_bearings()[..., 2] / 1000.0).astype("<f4")


def distance_image(distance_mm: np.ndarray, time_ns: int) -> dict:
    """(H, W) radial distance, mm -> ``Image`` ``32FC1`` of radial distance in m."""
    return _image(distance_m(distance_mm), "32FC1", time_ns)


def depth_image(distance_mm: np.ndarray, camera: CameraModel, time_ns: int) -> dict:
    """(H, W) radial distance, mm -> ``Image`` ``32FC1`` of z depth in m (REP 118)."""
    return _image(depth_m(distance_mm, camera), "32FC1", time_ns)


def camera_info(camera: CameraModel, time_ns: int) -> dict:
    """``sensor_msgs/msg/CameraInfo``: the pinhole K, OpenCV's (k1, k2, p1, p2, k3) as
    ``plumb_bob``, R = I, P = [K | 0] (a monocular camera), no binning, full ROI."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    return {
        "header": header(time_ns, topics.CAMERA_OPTICAL_FRAME_ID),
        "height": camera.height,
        "width": camera.width,
        "distortion_model": "plumb_bob",
        "d": [float(v) for v in np.asarray(camera.dist, float)],
        "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def quaternion(R: np.ndarray) -> dict:
    """Rotation (3, 3) -> ``geometry_msgs/msg/Quaternion`` (x, y, z, w), w >= 0."""
    w, x, y, z = (float(v) for v in quaternion_wxyz_from_rotation(np.asarray(R, float)))
    return {"x": x, "y": y, "z": z, "w": w}


def vector_m(v_mm: np.ndarray) -> dict:
    """(3,) mm (or mm/s) -> ``Vector3`` / ``Point`` fields x, y, z in m (m/s)."""
    x, y, z = (float(c) / 1000.0 for c in np.asarray(v_mm, float))
    return {"x": x, "y": y, "z": z}


def pose_with_covariance(
    R: np.ndarray, t_mm: np.ndarray, covariance: np.ndarray, time_ns: int
) -> dict:
    """``geometry_msgs/msg/PoseWithCovarianceStamped`` of T_camera_target (R (3, 3), t
    (3,) mm) in the camera optical frame; ``covariance`` (6, 6) over (rotation vector rad,
    translation mm), ours, written in ROS's order and units (``ros2_covariance``)."""
    return {
        "header": header(time_ns, topics.CAMERA_OPTICAL_FRAME_ID),
        "pose": {
            "pose": {"position": vector_m(t_mm), "orientation": quaternion(R)},
            "covariance": ros_covariance_row_major(covariance),
        },
    }


def twist_with_covariance(
    angular_rate_rad_s: np.ndarray,
    velocity_mm_s: np.ndarray,
    covariance: np.ndarray,
    time_ns: int,
) -> dict:
    """``geometry_msgs/msg/TwistWithCovarianceStamped`` of the target in the camera
    optical frame: linear = the target origin's velocity (3,) mm/s -> m/s, angular = its
    angular rate (3,) rad/s (``dR/dt = [w]x R``), both in the camera frame;
    ``covariance`` (6, 6) over (rate rad/s, velocity mm/s), ours, in ROS's order
    (linear first) and units."""
    w = [float(v) for v in np.asarray(angular_rate_rad_s, float)]
    return {
        "header": header(time_ns, topics.CAMERA_OPTICAL_FRAME_ID),
        "twist": {
            "twist": {
                "linear": vector_m(velocity_mm_s),
                "angular": {"x": w[0], "y": w[1], "z": w[2]},
            },
            "covariance": ros_covariance_row_major(covariance),
        },
    }


def transform(R: np.ndarray, t_mm: np.ndarray, parent: str, child: str, time_ns: int) -> dict:
    """``geometry_msgs/msg/TransformStamped`` T_parent_child (R (3, 3), t (3,) mm):
    the child frame's origin and axes in the parent frame, m."""
    return {
        "header": header(time_ns, parent),
        "child_frame_id": child,
        "transform": {"translation": vector_m(t_mm), "rotation": quaternion(R)},
    }


def tf_message(transforms: list[dict]) -> dict:
    """``tf2_msgs/msg/TFMessage`` of ``transform``'s messages."""
    return {"transforms": transforms}


def camera_link_transform(time_ns: int) -> dict:
    """The static camera_link -> camera optical frame (REP 103), no translation."""
    return transform(
        R_LINK_OPTICAL,
        np.zeros(3),
        topics.CAMERA_LINK_FRAME_ID,
        topics.CAMERA_OPTICAL_FRAME_ID,
        time_ns,
    )
