"""The reference pose check (``tofpose.stages.pose.reference.verify.pose_check``) against the
compiled one (``kernels.verify.pose_check``) on rendered frames and random poses, and
against poses whose verdict is known. Tolerance: the outcome and reflector equal, (u, v)
to 1e-9 px (OpenCV's projection against the kernel's)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.core.records import camera_record, catalog_record
from tofpose.stages.pose import constants as codes
from tofpose.stages.pose.kernels import verify as kernel
from tofpose.stages.pose.reference import verify as reference

CAM, CAT = CameraModel(), paper_target()


def _both(T, gray, matched, threshold=400.0, dark_check=True, dist=None):
    camera = camera_record(CAM)
    if dist is not None:
        camera = camera._replace(dist=dist)
    args = (catalog_record(CAT), matched, T.R, T.t_mm, camera, gray, threshold, dark_check)
    got, want = reference.pose_check(*args), kernel.pose_check(*args)
    assert got[:2] == want[:2]
    np.testing.assert_allclose(got[2:], want[2:], atol=1e-9)
    return got


@pytest.mark.parametrize("distance_mm", [800.0, 2000.0, 5000.0, 10000.0])
def test_rendered_frames_are_consistent_and_a_missing_marker_is_found(distance_mm):
    """A rendered frame is consistent at its true pose, and (unmatched, far enough
    apart to be tested) a marker painted out of it is the dark one named."""
    T = facing_pose(distance_mm, 3, -5, 10, offset_mm=(60.0, -40.0))
    frame = render(T, seed=2)
    n = len(CAT)
    threshold = 0.5 * float(np.percentile(frame.gray, 99.9))
    assert _both(T, frame.gray, np.zeros(n, bool), threshold)[0] == codes.CONSISTENT
    uv = CAM.project(CAT.positions_mm @ T.R.T + T.t_mm)
    found = 0
    for i in range(n):
        gray = frame.gray.copy()
        d_px = CAM.fx * CAT.diameters_mm[i] / (CAT.positions_mm[i] @ T.R[2] + T.t_mm[2])
        u, v, half = int(uv[i, 0]), int(uv[i, 1]), int(d_px) + 2
        gray[max(v - half, 0) : v + half + 1, max(u - half, 0) : u + half + 1] = 0
        matched = np.ones(n, bool)
        matched[i] = False
        outcome, j, _, _ = _both(T, gray, matched, threshold)
        assert outcome in (codes.CONSISTENT, codes.DARK_REFLECTOR)
        if outcome == codes.DARK_REFLECTOR:
            assert j == i
            found += 1
    assert found > 0


def test_random_poses_and_frames_agree_with_the_kernel():
    """Random poses (some behind the camera), random sparse frames, random matched sets,
    with and without lens distortion."""
    rng = np.random.default_rng(5)
    outcomes = set()
    for trial in range(400):
        R = (
            rotation_from_euler_deg(*rng.uniform(-60, 60, 2), rng.uniform(-180, 180))
            @ facing_pose(1.0).R
        )
        if trial % 10 == 0:
            R = rotation_from_euler_deg(0, 100, 0) @ R  # likely facing away / behind
        T = RigidTransform(R, np.array([*rng.uniform(-400, 400, 2), rng.uniform(150, 9000)]))
        gray = (rng.random((240, 320)) < rng.uniform(0, 0.2)).astype(np.float32) * 1000
        matched = rng.random(len(CAT)) < 0.3
        dist = None if trial % 2 else np.array([-0.1, 0.02, 1e-3, -1e-3, 0.0])
        outcomes.add(_both(T, gray, matched, 500.0, bool(trial % 7), dist)[0])
    assert outcomes == {0, 1, 2}


def test_a_pose_facing_away_is_refused_as_the_kernel_refuses_it():
    """The plate turned 90 deg at 150 mm: reflectors behind the camera, BEHIND_CAMERA;
    a frame with no active pixel at the true pose names the first clear reflector."""
    T = facing_pose(150.0)
    R = T.R @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    lit = np.full((240, 320), 1000.0, np.float32)
    assert _both(RigidTransform(R, T.t_mm), lit, np.zeros(len(CAT), bool))[0] == (
        codes.BEHIND_CAMERA
    )
    T = facing_pose(2000.0)
    dark = np.zeros((240, 320), np.float32)
    outcome, i, u, v = _both(T, dark, np.zeros(len(CAT), bool))
    assert outcome == codes.DARK_REFLECTOR
    np.testing.assert_allclose((u, v), CAM.project((CAT.positions_mm[i] @ T.R.T + T.t_mm)[None])[0])
    assert _both(T, np.full((240, 320), 400.0, np.float32), np.zeros(len(CAT), bool))[0] == (
        codes.CONSISTENT
    )
    assert _both(T, dark, np.zeros(len(CAT), bool), dark_check=False)[0] == codes.CONSISTENT
