"""Pose kernels against NumPy."""

from __future__ import annotations

import numpy as np

from tofpose.geometry import rotation_from_euler_deg
from tofpose.kernels.pose import facing_cosine


def test_facing_cosine_is_the_cosine_of_the_view_angle():
    rng = np.random.default_rng(2)
    centroid = rng.normal(0, 100, 3)
    for _ in range(200):
        R = rotation_from_euler_deg(*rng.uniform(-180, 180, 3))
        t = rng.normal(0, 500, 3) + [0, 0, 3000]
        to_camera = -(R @ centroid + t)
        want = R[:, 2] @ to_camera / np.linalg.norm(to_camera)
        assert abs(facing_cosine(R, t, centroid) - want) < 1e-14
