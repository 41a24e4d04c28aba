"""The compiled pose check (``kernels.verify.pose_check``) on poses whose verdict is
known."""

from __future__ import annotations

import numpy as np

from tests.conftest import facing_pose
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.core.records import camera_record, catalog_record
from tofpose.stages.pose.constants import BEHIND_CAMERA, CONSISTENT, DARK_REFLECTOR
from tofpose.stages.pose.kernels.verify import pose_check


def _check(T, gray, matched, dark_check=True):
    cam, cat = CameraModel(), paper_target()
    return pose_check(
        catalog_record(cat), matched, T.R, T.t_mm, camera_record(cam), gray, 400.0, dark_check
    )


def test_a_lit_frame_is_consistent_and_a_dark_one_names_the_first_clear_reflector():
    T = facing_pose(2000.0)
    n = len(paper_target())
    lit = np.full((240, 320), 1000.0, np.float32)
    assert _check(T, lit, np.zeros(n, bool))[0] == CONSISTENT
    dark = np.zeros((240, 320), np.float32)
    outcome, i, u, v = _check(T, dark, np.zeros(n, bool))
    assert outcome == DARK_REFLECTOR and 0 <= i < n
    cam = CameraModel()
    centre = paper_target().positions_mm[i] @ T.R.T + T.t_mm
    np.testing.assert_allclose((u, v), cam.project(centre[None])[0])
    # matched reflectors are not tested, nor is anything without the dark check
    assert _check(T, dark, np.ones(n, bool))[0] == CONSISTENT
    assert _check(T, dark, np.zeros(n, bool), dark_check=False)[0] == CONSISTENT
    # lit exactly at I_t counts as active (the set is gray >= I_t)
    assert _check(T, np.full((240, 320), 400.0, np.float32), np.zeros(n, bool))[0] == CONSISTENT


def test_a_pose_with_a_reflector_behind_the_camera_is_refused():
    T = facing_pose(150.0)  # the plate is wider than its distance: tilt it through z = 0
    R = T.R @ np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    lit = np.full((240, 320), 1000.0, np.float32)
    outcome = _check(RigidTransform(R, T.t_mm), lit, np.zeros(len(paper_target()), bool))[0]
    assert outcome == BEHIND_CAMERA
