"""Our pose and twist covariances in ROS's order and units (docs/interop.md, "ROS 2").

Ours (``PoseResult.covariance``, ``RelativeState.covariance``): a pose perturbation is
``(w, dt)``, ``R <- exp([w]x) R`` and ``t <- t + dt``, with the rotation vector w (rad) and
dt (mm) both in the camera frame (a left perturbation: rotations about the camera's fixed
axes); the covariance's order is (w_x, w_y, w_z, dt_x, dt_y, dt_z). The relative state's
twist block is (dw rad/s, dv mm/s) in the same frame.

ROS's (``geometry_msgs/msg/PoseWithCovariance``): (x, y, z, rotation about X, about Y,
about Z) in m and rad, "a fixed-axis representation": the rotations are about the axes
of the header's frame, which for our messages is the camera optical frame, the camera
frame itself. To first order a rotation by small angles about the fixed X, Y, Z axes is
the rotation vector about them, so ROS's rotX, rotY, rotZ are our w_x, w_y, w_z, about the
same axes: the conversion is a reordering (translation first) and mm -> m, nothing else.
They are NOT the (pitch, yaw, roll) Euler angles of ``R_facing`` that the dashboard and
reports show (``core.geometry.facing_euler_sigma_deg`` maps between the two). Twist
(``TwistWithCovariance``): (v_x, v_y, v_z, w_x, w_y, w_z) in m/s and rad/s, the same
reordering and mm -> m.
"""

from __future__ import annotations

import numpy as np

#: ROS's order (x, y, z, rotX, rotY, rotZ) as indices of ours (rotX, rotY, rotZ, x, y, z)
ROS_FROM_OURS = (3, 4, 5, 0, 1, 2)
#: ROS's units over ours, per ROS index: mm -> m for the linear three, rad stays rad
ROS_UNIT_SCALE = np.array([1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0])


def ros_covariance(covariance: np.ndarray) -> np.ndarray:
    """A (6, 6) covariance over (rotation rad, translation mm) [or (rate rad/s, velocity
    mm/s)] -> (6, 6) over ROS's (translation m, rotation rad) [(velocity m/s, rate rad/s)]:
    ``C_ros[i, j] = C[p_i, p_j] s_i s_j`` with p = ``ROS_FROM_OURS``, s = ``ROS_UNIT_SCALE``.
    ValueError naming the shape when it is not (6, 6)."""
    C = np.asarray(covariance, dtype=np.float64)
    if C.shape != (6, 6):
        raise ValueError(f"a pose or twist covariance is (6, 6), got shape {C.shape}")
    idx = np.array(ROS_FROM_OURS)
    return C[np.ix_(idx, idx)] * np.outer(ROS_UNIT_SCALE, ROS_UNIT_SCALE)


def ros_covariance_row_major(covariance: np.ndarray) -> list[float]:
    """``ros_covariance`` as the 36 row-major floats of a ``float64[36] covariance``."""
    return [float(v) for v in ros_covariance(covariance).ravel()]
