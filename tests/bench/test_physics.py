"""The physics robustness study (``bench/physics.py``): its draws stay in the ranges it
documents, and a short run judges every cell."""

from __future__ import annotations

import numpy as np

from bench import physics
from tofpose import CameraModel
from tofpose.geometry import rotation_angle_deg
from tofpose.sim.bench import R_FACING


def test_poses_are_at_the_range_in_view_and_within_the_attitude_spread():
    cam, rng = CameraModel(), np.random.default_rng(0)
    for range_m in physics.RANGES_M:
        for _ in range(50):
            T = physics.draw_pose(range_m, rng, cam)
            assert abs(np.linalg.norm(T.t_mm) - range_m * 1000.0) < 1e-6
            u, v = cam.project(T.t_mm[None])[0]
            assert abs(u - cam.cx) <= physics.OFFSET_FRACTION * cam.width / 2 + 1e-6
            assert abs(v - cam.cy) <= physics.OFFSET_FRACTION * cam.height / 2 + 1e-6
            # three Euler angles of at most 20 deg: at most 20 sqrt(3) deg from facing
            assert rotation_angle_deg(T.R, R_FACING) <= physics.MAX_ATTITUDE_DEG * 3**0.5


def test_each_family_draws_its_own_knobs_in_their_ranges():
    rng = np.random.default_rng(1)
    for _ in range(30):
        scene, sensor = physics.draw_physics("ideal", rng, 8)
        assert (scene.plate_reflectance, sensor.blur_sigma_px, scene.reflector_gains) == (
            0.10, 0.0, None)  # fmt: skip
        scene, _ = physics.draw_physics("grey plate", rng, 8)
        assert 0.25 <= scene.plate_reflectance <= 0.6 and scene.wall_distance_mm is None
        _, sensor = physics.draw_physics("lens blur", rng, 8)
        assert 0.3 <= sensor.blur_sigma_px <= 1.5 and 0 <= sensor.psf_halo_fraction <= 0.1
        scene, _ = physics.draw_physics("gains", rng, 8)
        assert len(scene.reflector_gains) == 8
        assert all(0.7 <= g <= 1.3 for g in scene.reflector_gains)
        assert 2.0 <= scene.retro_falloff_exponent <= 6.0
        scene, sensor = physics.draw_physics("all", rng, 8)
        assert 1000.0 <= sensor.ambient_lux <= 10000.0 and sensor.blur_sigma_px >= 0.3


def test_a_short_run_judges_every_cell_and_reports_it(tmp_path):
    out = physics.run(1)
    assert set(out) == {(f, r) for f in physics.FAMILIES for r in physics.RANGES_M}
    for summary, _ in out.values():
        assert summary["frames"] == 1
        assert summary["success_pct"] in (0.0, 100.0)
    # the ideal sensor at 3 m is the easy cell: its one frame succeeds
    assert out[("ideal", 3.0)][0]["success_pct"] == 100.0
    text = physics.markdown(out, "physics.png", 1)
    assert text.count("\n|") == 2 + len(out)  # header, rule and one row per cell
    physics.plot(out, tmp_path / "physics.png")
    assert (tmp_path / "physics.png").stat().st_size > 10_000
