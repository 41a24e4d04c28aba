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
from tofpose.sim.render import SensorModel

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


def test_draw_frame_draws_the_seven_families_exactly_as_the_three_calls_do():
    """The families of ``FAMILIES`` keep their frames: ``draw_frame`` then ``render``
    from one stream gives the frame ``draw_physics``, ``draw_pose``,
    ``draw_background`` and ``render_frame`` give from the same stream, bit for bit."""
    from tofpose.sim.randomise import FAMILIES, draw_background, draw_frame
    from tofpose.sim.render import render_frame

    cam = CameraModel()
    for k, family in enumerate(FAMILIES):
        a, b = np.random.default_rng([7, k]), np.random.default_rng([7, k])
        d = draw_frame(family, 4.5, a, CAT, max_attitude_deg=15.0, offset_fraction=0.4)
        fa = d.render(a)
        scene, sensor = draw_physics(family, b, CAT)
        T = draw_pose(4.5, b, cam, 15.0, 0.4)
        scene = draw_background(family, scene, b, cam, T)
        fb = render_frame(cam, scene, T, sensor, b)
        assert d.camera == cam and d.glints is None
        assert np.array_equal(fa.gray, fb.gray), family
        assert np.array_equal(fa.distance_mm, fb.distance_mm, equal_nan=True), family
        assert a.bit_generator.state == b.bit_generator.state


def test_the_extra_families_are_drawn_only_whole_and_unknown_ones_are_named():
    from tofpose.sim.randomise import EXTRA_FAMILIES, camera_for

    rng = np.random.default_rng(4)
    for family in EXTRA_FAMILIES:
        with pytest.raises(ValueError, match="draw_frame"):
            draw_physics(family, rng, CAT)
    with pytest.raises(ValueError, match="'fog'"):
        camera_for("fog")


def test_a_fixed_exposure_brings_a_facing_reflector_to_its_overexposure():
    """``fixed_exposure(..., 3000 mm, 3.0)``: a reflector facing the camera at 3 m
    returns 3x full scale (noiseless amplitude of the pixels inside a disc, scaled to
    each pixel's distance and incidence), on the EPC660 and on a camera of count scale
    4, whose auto exposure aims at the same reference level."""
    from tests.conftest import facing_pose
    from tofpose.sim.randomise import fixed_exposure, other_sensor_camera
    from tofpose.sim.render import render_frame
    from tofpose.sim.scene import FIRST_DISC, TargetScene

    T = facing_pose(3000.0)
    for cam in (CameraModel(), other_sensor_camera()):
        base = SensorModel(noise=False, supersampling=1)
        sensor = fixed_exposure(base, cam, 3000.0, 3.0)
        assert not sensor.auto_exposure and sensor.integration_time_us > 4000.0
        f = render_frame(cam, TargetScene(CAT), T, sensor)
        disc = f.surface_id >= FIRST_DISC
        e = cam.pixel_bearings()[disc]
        cos_inc = -(e @ T.R[:, 2])
        d = f.true_distance_mm[disc]
        expected = 3.0 * 4095.0 * (3000.0 / d) ** 2 * cos_inc**4  # cos^3 fall-off x cos
        np.testing.assert_allclose(f.amplitude[disc], expected, rtol=1e-9)


def test_saturating_frames_have_clipped_cores_without_distance_and_measured_rims():
    """Each frame of ``saturating``: an overexposure of 2-5x (read back from its
    exposure); every marker in view has its pixels' centres clipped at full scale with
    no distance (NaN), as a ToF camera reports a saturated pixel; every clipped pixel has
    no distance; and each marker keeps measured rim pixels (a distance, below full
    scale) around its core."""
    import cv2

    from tofpose.sim.randomise import draw_frame
    from tofpose.sim.scene import FIRST_DISC

    rng = np.random.default_rng(6)
    for range_m in (3.0, 4.5, 6.0, 8.0):
        d = draw_frame("saturating", range_m, rng, CAT)
        f = d.render(rng)
        s, r_mm = d.sensor, float(np.linalg.norm(d.T_camera_target.t_mm))
        over = s.integration_time_us * s.illumination_gain * s.retro_gain / r_mm**2 / 4095.0
        assert not s.auto_exposure and 2.0 <= over <= 5.0
        clipped = f.gray == 4095
        assert np.isnan(f.distance_mm[clipped]).all()
        for k in range(len(CAT)):
            core = f.surface_id == FIRST_DISC + k
            if not core.any():
                continue
            assert clipped[core].all() and np.isnan(f.distance_mm[core]).all()
            ring = cv2.dilate(core.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
            rim = ring & ~core & np.isfinite(f.distance_mm) & (f.gray < 4095)
            assert rim.any(), (range_m, k)


def test_glints_frames_carry_15_glints_at_the_targets_range_that_light_their_pixels():
    from dataclasses import replace

    from tofpose.sim.randomise import draw_frame
    from tofpose.sim.render import render_frame

    rng = np.random.default_rng(8)
    for range_m in (3.0, 8.0):
        d = draw_frame("glints", range_m, rng, CAT)
        g = d.glints
        assert g is not None and len(g) == 15
        assert np.all(np.abs(g.range_mm - np.linalg.norm(d.T_camera_target.t_mm)) <= 250.0)
        quiet = replace(d, sensor=replace(d.sensor, noise=False))
        f = quiet.render(rng)
        plain = render_frame(d.camera, d.scene, d.T_camera_target, quiet.sensor)
        u, v = np.rint(d.camera.project(g.positions_mm)).astype(int).T
        # at least the share of a sigma-0.5 spot half a pixel off each axis: 0.36 of its peak
        lit = np.minimum(plain.gray[v, u] + 0.35 * g.peak_counts, 4095)
        assert np.all(f.gray[v, u] >= lit)


def test_the_other_sensor_is_640_by_480_at_20_mhz_with_4x_the_counts():
    """``other sensor``: its frames are 640 x 480 through a camera with the EPC660's
    field of view; the same return reads 4x the counts, and its distance noise follows
    its 20 MHz modulation: the markers' pixels scatter 6/20 as much as on the EPC660."""
    from tests.conftest import facing_pose
    from tofpose.sim.randomise import draw_frame, other_sensor_camera
    from tofpose.sim.render import render_frame, sensor_for_camera
    from tofpose.sim.scene import FIRST_DISC, TargetScene

    rng = np.random.default_rng(9)
    d = draw_frame("other sensor", 6.0, rng, CAT)
    assert d.camera.shape == (480, 640) and d.camera.fx == 650.0
    assert d.sensor.modulation_frequency_hz == 20e6 == d.camera.modulation_frequency_hz
    assert d.render(rng).gray.shape == (480, 640)
    ref = CameraModel()  # the same field of view: the same half width over focal length
    assert (d.camera.width / d.camera.fx, d.camera.height / d.camera.fy) == (
        ref.width / ref.fx,
        ref.height / ref.fy,
    )
    assert (d.camera.cx, d.camera.cy) == ((d.camera.width - 1) / 2, (d.camera.height - 1) / 2)

    T = facing_pose(3000.0)
    spread, peak = [], []
    for cam in (CameraModel(), other_sensor_camera()):
        sensor = sensor_for_camera(SensorModel(supersampling=1), cam)
        f = render_frame(cam, TargetScene(CAT), T, sensor, np.random.default_rng(1))
        core = f.surface_id == FIRST_DISC + 5  # an 80 mm marker
        spread.append(np.std(f.distance_mm[core] - f.true_distance_mm[core]))
        peak.append(np.median(f.gray[core]))
    assert peak[1] / peak[0] == pytest.approx(4.0, rel=0.02)
    assert spread[1] / spread[0] == pytest.approx(6.0 / 20.0, rel=0.25)


def test_bright_plate_frames_have_a_light_plate_and_weaker_reflectors_in_their_ranges():
    """``bright plate``: plate reflectance 0.6-0.95 and no wall, each reflector's gain
    0.7-1.3, the retro-reflector gain within 4-40 (log-uniform: both ends drawn). A
    face-on marker's core then reads retro gain x its gain / reflectance times the
    plate (to 20 %: the plate's pixels are not all face-on), which the family's ranges
    put at 2.9-87x, and the plate sits far above the noise."""
    from tests.conftest import facing_pose
    from tofpose.sim.randomise import (
        BRIGHT_PLATE_REFLECTANCE,
        BRIGHT_PLATE_RETRO_GAIN,
        bright_plate,
        draw_frame,
    )
    from tofpose.sim.render import render_frame
    from tofpose.sim.scene import FIRST_DISC, PLATE, TargetScene

    rng = np.random.default_rng(12)
    gains = []
    for _ in range(40):
        d = draw_frame("bright plate", 4.5, rng, CAT)
        assert 0.6 <= d.scene.plate_reflectance <= 0.95
        assert d.scene.wall_distance_mm is None
        assert len(d.scene.reflector_gains) == len(CAT)
        assert all(0.7 <= g <= 1.3 for g in d.scene.reflector_gains)
        gains.append(d.sensor.retro_gain)
    assert 4.0 <= min(gains) < 8.0 and 20.0 < max(gains) <= 40.0
    lo = BRIGHT_PLATE_RETRO_GAIN[0] * 0.7 / BRIGHT_PLATE_REFLECTANCE[1]
    hi = BRIGHT_PLATE_RETRO_GAIN[1] * 1.3 / BRIGHT_PLATE_REFLECTANCE[0]
    assert (round(lo, 1), round(hi)) == (2.9, 87)
    for _ in range(4):
        scene, sensor = bright_plate(TargetScene(CAT), SensorModel(noise=False), rng, len(CAT))
        f = render_frame(CameraModel(), scene, facing_pose(3000.0), sensor)
        plate = np.median(f.gray[f.surface_id == PLATE])
        core = np.median(f.gray[f.surface_id == FIRST_DISC + 5])  # an 80 mm marker
        model = sensor.retro_gain * scene.reflector_gains[5] / scene.plate_reflectance
        assert core / plate == pytest.approx(model, rel=0.2)
        assert plate > 20.0


def test_out_of_view_frames_put_part_of_the_target_outside_the_image():
    """``out of view``: the target's centre lies 0.85-1.2 half fields of view towards
    an edge, every edge drawn, so some of its markers project outside the image and
    some inside (in most frames)."""
    from tofpose.sim.randomise import EDGE_OFFSET, draw_frame

    rng = np.random.default_rng(9)
    sides, split = set(), 0
    for _ in range(40):
        d = draw_frame("out of view", 4.5, rng, CAT)
        cam, T = d.camera, d.T_camera_target
        u, v = cam.project((T.t_mm)[None])[0]
        off = max(abs(u - cam.cx) / (cam.width / 2), abs(v - cam.cy) / (cam.height / 2))
        assert EDGE_OFFSET[0] - 0.02 <= off <= EDGE_OFFSET[1] + 0.02
        sides.add(
            (
                np.sign(round(u - cam.cx)),
                np.sign(round(v - cam.cy)),
                off == abs(u - cam.cx) / (cam.width / 2),
            )
        )
        uv = cam.project(CAT.positions_mm @ T.R.T + T.t_mm)
        inside = (
            (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        )
        split += int(0 < inside.sum() < len(CAT))
    assert split >= 24  # most of the 40
    assert len({(s[2], s[0] if s[2] else s[1]) for s in sides}) == 4  # all four edges
