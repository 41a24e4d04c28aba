"""What the 3-D scene shows, against geometry computed by hand."""

from __future__ import annotations

import numpy as np

from backend.services.live.scene_model import (
    MATCHED,
    OUT_OF_VIEW,
    UNMATCHED,
    distance_cloud,
    lab_camera_pose,
    reflector_states,
)
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.pipeline import MatchedReflector, PoseResult

FACING = np.diag([1.0, -1.0, -1.0])  # target z towards the camera


def _result(matched_ids: list[int]) -> PoseResult:
    found = [MatchedReflector(i, np.zeros(2), np.zeros(3), 0.0, 2000.0, 10) for i in matched_ids]
    return PoseResult(True, matched=found)


def test_a_face_on_target_in_the_middle_of_the_image_has_every_reflector_in_view():
    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(FACING, np.array([0.0, 0.0, 2000.0]))
    states = reflector_states(cat, _result([1, 2, 5]), cam, T)
    by_id = dict(zip(cat.ids.tolist(), states, strict=True))
    assert [by_id[i] for i in (1, 2, 5)] == [MATCHED] * 3
    assert [by_id[i] for i in (3, 4, 6, 7, 8)] == [UNMATCHED] * 5


def test_a_target_turned_away_or_outside_the_image_is_out_of_view():
    cam, cat = CameraModel(), paper_target()
    away = RigidTransform(np.eye(3), np.array([0.0, 0.0, 2000.0]))  # plate normal along +z
    assert reflector_states(cat, _result([]), cam, away) == [OUT_OF_VIEW] * 8
    aside = RigidTransform(FACING, np.array([5000.0, 0.0, 2000.0]))  # far right of the FOV
    assert reflector_states(cat, _result([]), cam, aside) == [OUT_OF_VIEW] * 8
    assert reflector_states(cat, _result([]), cam, None) == [OUT_OF_VIEW] * 8


def test_reflectors_beyond_the_image_edge_are_out_of_view_the_rest_in_view():
    cam, cat = CameraModel(), paper_target()
    # Shift the target so that the image's right edge falls between x = 100 and x = 330 mm.
    z = 2000.0
    x_edge = (cam.width - 1 - cam.cx) * z / cam.fx  # lateral offset of the right edge at z
    T = RigidTransform(FACING, np.array([x_edge - 200.0, 0.0, z]))
    states = dict(zip(cat.ids.tolist(), reflector_states(cat, _result([]), cam, T), strict=True))
    # Reflectors 7, 8 (x = 330, 420) sit right of the edge, 1-6 (x <= 100) left of it.
    assert states[7] == states[8] == OUT_OF_VIEW
    assert all(states[i] == UNMATCHED for i in range(1, 7))


def test_the_distance_cloud_back_projects_each_kept_pixel_and_respects_the_point_budget():
    cam = CameraModel()
    d = np.full(cam.shape, 3000.0, np.float32)
    d[:10] = np.nan  # invalid rows are left out
    g = np.arange(d.size, dtype=np.uint16).reshape(d.shape)
    cloud = distance_cloud(cam, g, d, max_points=5000)
    assert len(cloud.points_m) <= 5000
    assert cloud.step == int(np.ceil(np.sqrt(cam.width * cam.height / 5000)))
    # every point lies on the 3 m sphere around the camera, in front of it
    np.testing.assert_allclose(np.linalg.norm(cloud.points_m, axis=1), 3.0, rtol=1e-5)
    assert (cloud.points_m[:, 2] > 0).all()
    # the top-left kept pixel (row 10 rounded up to the stride) maps back onto itself
    v0 = int(np.ceil(10 / cloud.step)) * cloud.step
    uv = cam.project(cloud.points_m[:1].astype(np.float64) * 1000.0)
    np.testing.assert_allclose(uv[0], [0.0, v0], atol=1e-3)
    assert cloud.colours.shape == (len(cloud.points_m), 3) and cloud.colours.dtype == np.uint8


def test_the_camera_rides_the_turntable():
    assert np.allclose(lab_camera_pose(None).as_matrix(), np.eye(4))
    T = lab_camera_pose({"yaw": 30.0, "rail": 1000.0})
    np.testing.assert_allclose(T.t_mm, [0.0, 0.0, 1000.0])
    np.testing.assert_allclose(T.R, rotation_from_euler_deg(0.0, 30.0, 0.0), atol=1e-12)
