"""Rotations, the Euler convention and rigid transforms (numpy + scipy only).

Conventions (docs/architecture.md §3): ``T_a_b`` maps points of frame b into frame a,
``y = R_a_b @ x + t_a_b``. Euler angles are (pitch, yaw, roll) with
``R = Rz(roll) @ Ry(yaw) @ Rx(pitch)``, i.e. scipy's extrinsic ``"xyz"`` sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

EULER_SEQUENCE = "xyz"  # extrinsic x (pitch), then y (yaw), then z (roll)


def rotation_from_euler_deg(pitch_deg: float, yaw_deg: float, roll_deg: float) -> np.ndarray:
    """Rotation matrix, shape (3, 3), ``Rz(roll) @ Ry(yaw) @ Rx(pitch)`` from (pitch,
    yaw, roll) in degrees."""
    return Rotation.from_euler(
        EULER_SEQUENCE, [pitch_deg, yaw_deg, roll_deg], degrees=True
    ).as_matrix()


def euler_deg_from_rotation(R: np.ndarray) -> np.ndarray:
    """(pitch, yaw, roll) in degrees, shape (3,), of a rotation matrix of shape (3, 3).

    Closed form of ``R = Rz(roll) Ry(yaw) Rx(pitch)`` (``R[2, 0] = -sin(yaw)``); the same
    angles as scipy's extrinsic ``"xyz"`` away from yaw = +-90 deg (gimbal lock, where
    only pitch - roll is defined and roll is set to 0), at a fraction of the cost.
    """
    (r00, _, _), (r10, r11, r12), (r20, r21, r22) = np.asarray(R, float).tolist()
    return _euler_deg(r00, r10, r11, r12, r20, r21, r22)


def _euler_deg(r00, r10, r11, r12, r20, r21, r22) -> np.ndarray:
    """``euler_deg_from_rotation`` from the seven elements it reads."""
    c_yaw = math.hypot(r00, r10)
    yaw = math.atan2(-r20, c_yaw)
    if c_yaw > 1e-9:
        pitch, roll = math.atan2(r21, r22), math.atan2(r10, r00)
    else:  # gimbal lock: fold everything into pitch
        pitch, roll = math.atan2(-r12, r11), 0.0
    return np.array([math.degrees(pitch), math.degrees(yaw), math.degrees(roll)])


FACING = np.diag([1.0, -1.0, -1.0])  # R_camera_target of a target squarely facing the camera


def facing_euler_deg(R_camera_target: np.ndarray) -> np.ndarray:
    """(pitch, yaw, roll) in degrees, shape (3,), of ``R_camera_target @ diag(1, -1, -1)``:
    the attitude as people read it (docs/architecture.md §3). A target squarely facing
    the camera reads (0, 0, 0) instead of (+/-180, 0, 0), so it never flips sign."""
    # R @ diag(1, -1, -1) negates columns 1 and 2: the elements negated one by one (NumPy
    # on a 3 x 3 costs more than the arithmetic); + 0.0 keeps zeros positive, as the
    # product gives them (atan2 tells -0.0 from 0.0)
    (r00, _, _), (r10, r11, r12), (r20, r21, r22) = np.asarray(R_camera_target, float).tolist()
    return _euler_deg(r00, r10, -r11 + 0.0, -r12 + 0.0, r20, -r21 + 0.0, -r22 + 0.0)


#: step of the numerical derivative of the Euler angles by the rotation vector, rad
_EULER_STEP_RAD = 1e-6


def facing_euler_sigma_deg(R_camera_target: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """1-sigma (3,) in deg of (pitch, yaw, roll) as ``facing_euler_deg`` reads them, from
    a pose covariance (6, 6) or (3, 3) whose first three rows are the rotation vector
    (rad, left perturbation ``R <- exp([w]x) R``, as ``PoseResult.covariance``):
    ``sqrt(diag(J C J^T))`` with J (3, 3) the angles' derivative by w (central
    differences, differences wrapped to +/-180 deg). The rotation vector's own sigmas are
    about the camera's axes, not the Euler angles', and differ from these by the
    attitude (up to the yaw's 1/cos(pitch) near gimbal lock, where these grow without
    bound as they should). NaN where the covariance is not finite."""
    C = np.asarray(covariance, float)[:3, :3]
    if not np.all(np.isfinite(C)):
        return np.full(3, np.nan)
    R = np.asarray(R_camera_target, float)
    J = np.empty((3, 3))
    for k in range(3):
        w = np.zeros(3)
        w[k] = _EULER_STEP_RAD
        d = facing_euler_deg(Rotation.from_rotvec(w).as_matrix() @ R) - facing_euler_deg(
            Rotation.from_rotvec(-w).as_matrix() @ R
        )
        J[:, k] = ((d + 180.0) % 360.0 - 180.0) / (2.0 * _EULER_STEP_RAD)
    return np.sqrt(np.clip(np.diag(J @ C @ J.T), 0.0, None))


def quaternion_wxyz_from_rotation(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), shape (4,), with w >= 0, of a rotation matrix (3, 3).

    Shepperd's method: the largest of the four squared components is taken from the
    diagonal and the others from the off-diagonal sums, which keeps it accurate for any
    rotation.
    """
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(R, float).tolist()
    tr = r00 + r11 + r22
    diag = [tr, r00, r11, r22]
    k = diag.index(max(diag))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = [(r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        q = [(r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        q = [(r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s]
    norm = math.sqrt(sum(v * v for v in q))
    sign = 1.0 if q[0] >= 0 else -1.0
    return np.array([sign * v / norm for v in q])


def rotation_from_quaternion_wxyz(q_wxyz) -> np.ndarray:
    """Rotation matrix, shape (3, 3), of a unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in q_wxyz)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle in degrees of the relative rotation ``R_a^T R_b`` (geodesic distance)."""
    cos = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


@dataclass(frozen=True)
class RigidTransform:
    """A rigid transform ``T_a_b``: ``y = R @ x + t_mm``.

    Attributes
    ----------
    R : ndarray of shape (3, 3)
        Rotation ``R_a_b``.
    t_mm : ndarray of shape (3,)
        Origin of frame b expressed in frame a, millimetres.
    """

    R: np.ndarray
    t_mm: np.ndarray

    @staticmethod
    def identity() -> RigidTransform:
        return RigidTransform(np.eye(3), np.zeros(3))

    @staticmethod
    def from_euler_deg(
        pitch_deg: float, yaw_deg: float, roll_deg: float, t_mm=(0.0, 0.0, 0.0)
    ) -> RigidTransform:
        return RigidTransform(
            rotation_from_euler_deg(pitch_deg, yaw_deg, roll_deg), np.asarray(t_mm, float)
        )

    def apply(self, points_mm: np.ndarray) -> np.ndarray:
        """Map points of shape (N, 3) (or (3,)) from frame b into frame a."""
        return np.asarray(points_mm) @ self.R.T + self.t_mm

    def compose(self, other: RigidTransform) -> RigidTransform:
        """``T_a_b.compose(T_b_c) == T_a_c``."""
        return RigidTransform(self.R @ other.R, self.R @ other.t_mm + self.t_mm)

    def inverse(self) -> RigidTransform:
        return RigidTransform(self.R.T, -self.R.T @ self.t_mm)

    def as_matrix(self) -> np.ndarray:
        """Homogeneous matrix of shape (4, 4)."""
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.t_mm
        return T
