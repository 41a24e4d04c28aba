"""Shared fixtures: the paper camera and target, and simulated frames with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.camera import CameraModel
from tofpose.catalog import paper_target
from tofpose.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene


def facing_pose(distance_mm, pitch_deg=0.0, yaw_deg=0.0, roll_deg=0.0, offset_mm=(0.0, 0.0)):
    """T_camera_target for a target facing the camera, rotated by small Euler angles."""
    R = rotation_from_euler_deg(pitch_deg, yaw_deg, roll_deg) @ R_FACING
    return RigidTransform(R, np.array([offset_mm[0], offset_mm[1], distance_mm], float))


def render(T, *, seed=0, noise=True, scene=None, sensor=None, camera=None):
    camera = camera or CameraModel()
    sensor = sensor or SensorModel(noise=noise)
    rng = np.random.default_rng(seed) if noise else None
    return render_frame(camera, scene or TargetScene(), T, sensor, rng)


@pytest.fixture
def camera():
    return CameraModel()


@pytest.fixture
def catalog():
    return paper_target()
