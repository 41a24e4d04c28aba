"""The turntable's kinematic chain (docs/architecture.md §6): lab frame to inner axis.

Lab frame L: at all axes zero the camera frame coincides with L (x right, y down, z
towards the target); the rail translates the turntable along +z; then the outer yaw
axis (about y), the middle pitch axis (about x) and the inner roll axis (about z):

    T_lab_inner = Trans(0, 0, rail) . Ry(yaw) . Rx(pitch) . Rz(roll)

The camera rides the inner axis through its installation transform ``T_inner_camera``;
the target stands in the lab at ``T_lab_target``. Then, for any axis positions,

    T_camera_target = (T_lab_inner . T_inner_camera)^-1 . T_lab_target
"""

from __future__ import annotations

import numpy as np

from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg


def axes_transform(positions: dict[str, float]) -> RigidTransform:
    """T_lab_inner for axis positions (yaw, pitch, roll in deg; rail in mm)."""
    R = rotation_from_euler_deg(0.0, positions.get("yaw", 0.0), 0.0)
    R = R @ rotation_from_euler_deg(positions.get("pitch", 0.0), 0.0, 0.0)
    R = R @ rotation_from_euler_deg(0.0, 0.0, positions.get("roll", 0.0))
    return RigidTransform(R, np.array([0.0, 0.0, positions.get("rail", 0.0)]))


def camera_target(
    positions: dict[str, float], T_inner_camera: RigidTransform, T_lab_target: RigidTransform
) -> RigidTransform:
    """T_camera_target at these axis positions for a mount and a target placement."""
    return axes_transform(positions).compose(T_inner_camera).inverse().compose(T_lab_target)
