"""Topics, message types and frame ids of the ROS 2 MCAP export (docs/interop.md, "ROS 2").

ROS's conventions (REP 103, REP 105, REP 118), not ours: metres, radians, quaternions
(x, y, z, w), covariance over (x, y, z, rotX, rotY, rotZ). The camera frame of DESIGN.md
(x right, y down, z along the boresight) is exactly REP 103's camera *optical* frame, so
every pose is in ``CAMERA_OPTICAL_FRAME_ID`` as it is: ``T_camera_target`` is the
transform ``CAMERA_OPTICAL_FRAME_ID`` -> ``TARGET_FRAME_ID``. The camera's body frame
(REP 103: x forward, y left, z up) is its parent, by a constant rotation on ``/tf_static``,
for a lab to hang on its own tree (e.g. a static ``base_link`` -> ``tofpose_camera_link``).
"""

from __future__ import annotations

# the images, one namespace so that image_transport pairs each with CAMERA_INFO
AMPLITUDE = "/tofpose/camera/amplitude"  # sensor_msgs/msg/Image mono16: the gray image, counts
DISTANCE = "/tofpose/camera/distance"  # Image 32FC1: radial distance along the ray, m, NaN invalid
DEPTH = "/tofpose/camera/depth"  # Image 32FC1: z depth (REP 118), m, NaN invalid
CAMERA_INFO = "/tofpose/camera/camera_info"  # sensor_msgs/msg/CameraInfo, plumb_bob
# the estimate and the relative state (with the pipeline run)
POSE = "/tofpose/pose"  # geometry_msgs/msg/PoseWithCovarianceStamped: each frame's pose
STATE_POSE = "/tofpose/relative_state/pose"  # PoseWithCovarianceStamped: the filter's pose
STATE_TWIST = "/tofpose/relative_state/twist"  # geometry_msgs/msg/TwistWithCovarianceStamped
# transforms
TF = "/tf"  # tf2_msgs/msg/TFMessage: optical frame -> target, target_truth, target_reference
TF_STATIC = "/tf_static"  # TFMessage, once: camera_link -> camera optical frame

IMAGE_TYPE = "sensor_msgs/msg/Image"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
POSE_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
TWIST_TYPE = "geometry_msgs/msg/TwistWithCovarianceStamped"
TF_TYPE = "tf2_msgs/msg/TFMessage"

#: each topic's message type
TYPES = {
    AMPLITUDE: IMAGE_TYPE,
    DISTANCE: IMAGE_TYPE,
    DEPTH: IMAGE_TYPE,
    CAMERA_INFO: CAMERA_INFO_TYPE,
    POSE: POSE_TYPE,
    STATE_POSE: POSE_TYPE,
    STATE_TWIST: TWIST_TYPE,
    TF: TF_TYPE,
    TF_STATIC: TF_TYPE,
}

CAMERA_LINK_FRAME_ID = "tofpose_camera_link"  # REP 103 body frame: x forward, y left, z up
CAMERA_OPTICAL_FRAME_ID = "tofpose_camera_optical_frame"  # x right, y down, z forward
TARGET_FRAME_ID = "tofpose_target"  # the pipeline's estimate
TRUTH_FRAME_ID = "tofpose_target_truth"  # the recording's /truth
REFERENCE_FRAME_ID = "tofpose_target_reference"  # the recording's /reference (the lab's)

#: the MCAP profile name of the file (MCAP's ``profile`` header field)
MCAP_PROFILE = "ros2"
