"""Domain randomisation: each family draws its own knobs within the ranges its docstring
gives, poses are at the range, in view and within the attitude spread, and a caller's
ambient light is kept."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose import CameraModel, paper_target
from tofpose.core.geometry import rotation_angle_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.randomise import draw_physics, draw_pose

CAT = paper_target()


def test_poses_are_at_the_range_in_view_and_within_the_attitude_spread():
    cam, rng = CameraModel(), np.random.default_rng(0)
    for range_m in (3.0, 4.5, 6.0, 8.0):
        for _ in range(50):
            T = draw_pose(range_m, rng, cam)
            assert abs(np.linalg.norm(T.t_mm) - range_m * 1000.0) < 1e-6
            u, v = cam.project(T.t_mm[None])[0]
            assert abs(u - cam.cx) <= 0.5 * cam.width / 2 + 1e-6
            assert abs(v - cam.cy) <= 0.5 * cam.height / 2 + 1e-6
            # three Euler angles of at most 20 deg: at most 20 sqrt(3) deg from facing
            assert rotation_angle_deg(T.R, R_FACING) <= 20.0 * 3**0.5


def test_each_family_draws_its_own_knobs_in_their_ranges():
    rng = np.random.default_rng(1)
    for _ in range(30):
        scene, sensor = draw_physics("ideal", rng, CAT)
        assert (
            scene.plate_reflectance,
            sensor.blur_sigma_px,
            scene.reflector_gains,
            sensor.systematic,
        ) == (0.10, 0.0, None, None)
        scene, _ = draw_physics("grey plate", rng, CAT)
        assert 0.25 <= scene.plate_reflectance <= 0.6 and scene.wall_distance_mm is None
        _, sensor = draw_physics("lens blur", rng, CAT)
        assert 0.3 <= sensor.blur_sigma_px <= 1.5 and 0 <= sensor.psf_halo_fraction <= 0.1
        scene, _ = draw_physics("gains", rng, CAT)
        assert len(scene.reflector_gains) == 8
        assert all(0.7 <= g <= 1.3 for g in scene.reflector_gains)
        assert 2.0 <= scene.retro_falloff_exponent <= 6.0
        _, sensor = draw_physics("systematic", rng, CAT)
        e = sensor.systematic
        assert 0 <= e.wiggle_amplitudes_mm[0] <= 15 and 0 <= e.wiggle_amplitudes_mm[1] <= 5
        assert -10 <= e.amplitude_mm_per_decade <= 2 and -15 <= e.offset_mm <= 15
        assert 0 <= e.pixel_offset_corner_mm <= 10 and 0 <= e.pixel_offset_sigma_mm <= 4
        assert 0 <= e.scatter_fraction <= 0.008 and e.drift_mm_per_kelvin == 0
        scene, sensor = draw_physics("all", rng, CAT)
        assert 1000.0 <= sensor.ambient_lux <= 10000.0 and sensor.blur_sigma_px >= 0.3
        assert sensor.systematic is not None


def test_a_callers_ambient_is_kept_and_an_unknown_family_is_named():
    rng = np.random.default_rng(2)
    for family in ("ideal", "all"):
        _, sensor = draw_physics(family, rng, CAT, ambient_lux=25000.0)
        assert sensor.ambient_lux == 25000.0
    with pytest.raises(ValueError, match="'fog'"):
        draw_physics("fog", rng, CAT)


def test_the_background_family_puts_a_room_around_the_target_others_draw_nothing():
    from tofpose.sim.randomise import draw_background

    cam = CameraModel()
    rng = np.random.default_rng(3)
    scene, sensor = draw_physics("background", rng, CAT)
    assert scene.wall_distance_mm is None and 1000.0 <= sensor.ambient_lux <= 10000.0
    T = draw_pose(4.5, rng, cam)
    with_room = draw_background("background", scene, rng, cam, T)
    room = with_room.background
    assert room is not None and room.distance_mm.shape == (cam.height, cam.width)
    # the room lies behind the target, except an arm: without one, nothing along the
    # rays through the target's plate is nearer than the target
    from tofpose.sim.background import synthetic_room

    plate = CAT.plate_size_mm
    corners = np.array(
        [[sx * plate[0] / 2, sy * plate[1] / 2, 0.0] for sx in (-1, 1) for sy in (-1, 1)]
    )
    uv = cam.project(T.apply(corners))
    u0, v0 = np.floor(uv.min(axis=0)).astype(int)
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int)
    for _ in range(20):
        bare = synthetic_room(cam, rng, 4500.0, T.t_mm, arm_probability=0.0)
        assert np.min(bare.distance_mm[v0:v1, u0:u1]) > np.linalg.norm(T.t_mm) + 100.0
    state = rng.bit_generator.state
    assert draw_background("ideal", scene, rng, cam, T) is scene
    assert rng.bit_generator.state == state  # other families' streams are unchanged
