"""A study frame's error on each requirement axis, from the stored columns.

The axes of a campaign's verdict (``tofpose.lab.requirements.REQUIREMENT_AXES``):
position x, y, z (mm: estimate minus truth of the target's origin in the camera frame,
the store's ``err_x_mm`` ...) and attitude pitch, yaw, roll (deg: estimate minus truth
of the facing Euler angles of docs/architecture.md §3, wrapped to (-180, 180], from the
stored quaternions). A frame without a pose has NaN on every axis.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from tofpose.core.geometry import FACING

#: the store's columns each position axis reads
POSITION_COLUMNS = ("err_x_mm", "err_y_mm", "err_z_mm")
TRUE_QUATERNION = ("true_qw", "true_qx", "true_qy", "true_qz")
ESTIMATED_QUATERNION = ("est_qw", "est_qx", "est_qy", "est_qz")


def facing_euler_deg_many(q_wxyz: np.ndarray) -> np.ndarray:
    """(pitch, yaw, roll) in deg, shape (N, 3), of N rotations ``R_camera_target`` given
    as quaternions (w, x, y, z), shape (N, 4): ``tofpose.core.geometry.facing_euler_deg``
    for many at once (away from yaw = +-90 deg, which no study draws). Rows with a NaN
    quaternion give NaN."""
    q = np.asarray(q_wxyz, float).reshape(-1, 4)
    out = np.full((len(q), 3), np.nan)
    good = np.all(np.isfinite(q), axis=1)
    if not good.any():
        return out
    M = Rotation.from_quat(q[good], scalar_first=True).as_matrix() @ FACING  # (n, 3, 3)
    pitch = np.arctan2(M[:, 2, 1], M[:, 2, 2])
    yaw = np.arctan2(-M[:, 2, 0], np.hypot(M[:, 0, 0], M[:, 1, 0]))
    roll = np.arctan2(M[:, 1, 0], M[:, 0, 0])
    out[good] = np.degrees(np.stack([pitch, yaw, roll], axis=1))
    return out


def wrap_deg(angle_deg: np.ndarray) -> np.ndarray:
    """Angles (any shape) wrapped to (-180, 180] deg."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, float), 360.0)


def requirement_axis_errors(columns: dict[str, np.ndarray]) -> np.ndarray:
    """Errors of N frames on the six requirement axes (module docstring), shape (N, 6):
    x, y, z (mm), pitch, yaw, roll (deg); NaN rows where a frame has no pose.
    ``columns``: the store's columns (``tofpose.study.columns.COLUMNS``), each (N,)."""
    n = len(columns["frame"])
    ok = np.asarray(columns["ok"], bool)
    out = np.full((n, 6), np.nan)
    if not ok.any():
        return out
    q_true = np.stack([np.asarray(columns[c], float)[ok] for c in TRUE_QUATERNION], axis=1)
    q_est = np.stack([np.asarray(columns[c], float)[ok] for c in ESTIMATED_QUATERNION], axis=1)
    out[ok, :3] = np.stack([np.asarray(columns[c], float)[ok] for c in POSITION_COLUMNS], axis=1)
    out[ok, 3:] = wrap_deg(facing_euler_deg_many(q_est) - facing_euler_deg_many(q_true))
    return out
