"""Specular glints (``tofpose.sim.glints``): a glint rendered alone appears where it
projects, with its drawn light and its range; over a surface it mixes by phasor; the
drawn glints are where, how far and how bright the family says, and none is hidden."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.special import erf

from tests.conftest import facing_pose
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.sim.glints import Glints, draw_glints, glint_phasors, render_glints, target_image_box
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import PLATE, TargetScene
from tofpose.sim.systematic import SystematicErrors

#: a pose that puts the target out of view: the frame sees nothing
AWAY = RigidTransform(np.eye(3), np.array([9000.0, 0.0, 3000.0]))
EMPTY = TargetScene(wall_distance_mm=None)


def _glint(camera, uv, range_mm, sigma_px, peak_counts):
    p = camera.bearings(np.array([uv], float)) * range_mm
    return Glints(p, np.array([sigma_px]), np.array([peak_counts]))


def _alone(camera, glints, sensor, rng=None):
    frame = render_frame(camera, EMPTY, AWAY, sensor, rng)
    assert frame.gray.max() == 0  # nothing in view
    return render_glints(frame, glints, camera, sensor, rng)


@pytest.mark.parametrize(
    "camera", [CameraModel(), replace(CameraModel(), count_scale=4.0, full_scale_counts=16380.0)]
)
def test_a_glint_alone_appears_where_it_projects_with_its_light_and_its_range(camera):
    sensor = SensorModel(noise=False, ambient_lux=0.0)
    uv, sigma, peak = (100.3, 80.6), 0.9, 1500.0
    f = _alone(camera, _glint(camera, uv, 2500.0, sigma, peak), sensor)
    g = f.gray.astype(float) / camera.count_scale
    # its whole light, 2 pi sigma^2 peak (each pixel rounded to a count)
    flux = 2 * np.pi * sigma**2 * peak
    assert g.sum() == pytest.approx(flux, abs=0.5 * (g > 0).sum() / camera.count_scale + 1)
    vv, uu = np.mgrid[0 : camera.height, 0 : camera.width]
    np.testing.assert_allclose([(g * uu).sum() / g.sum(), (g * vv).sum() / g.sum()], uv, atol=0.01)
    # the pixel at (100, 81): the Gaussian's share of that pixel's area
    share = [
        0.5 * (erf((c + 0.5 - x) / (2**0.5 * sigma)) - erf((c - 0.5 - x) / (2**0.5 * sigma)))
        for c, x in ((100, uv[0]), (81, uv[1]))
    ]
    assert f.gray[81, 100] == round(camera.count_scale * flux * share[0] * share[1])
    # its range where its light is above the amplitude floor, no distance elsewhere
    read = f.amplitude >= sensor.min_amplitude_counts
    assert read.sum() >= 9
    np.testing.assert_allclose(f.distance_mm[read], 2500.0, atol=1e-3)
    assert np.isnan(f.distance_mm[~read]).all()


def test_over_a_surface_a_glint_mixes_with_it_by_phasor():
    """A glint 200 mm in front of the plate: each pixel reads the phase of the sum of the
    plate's phasor and the glint's (amplitude-weighted), between the two ranges."""
    cam = CameraModel()
    sensor = SensorModel(noise=False, supersampling=1)
    T = facing_pose(3000.0)
    plain = render_frame(cam, TargetScene(), T, sensor)
    uv = (120.0, 100.0)  # on the plate, away from the markers
    assert plain.surface_id[100, 120] == PLATE
    gl = _glint(cam, uv, 2800.0, 1.2, 300.0)
    f = render_glints(plain, gl, cam, sensor)
    k = sensor.mm_per_radian
    g_re, g_im, _ = glint_phasors(gl, cam, sensor)
    win = np.s_[94:107, 114:127]
    z = (
        plain.amplitude[win] * np.exp(1j * plain.true_distance_mm[win] / k)
        + g_re[win]
        + 1j * g_im[win]
    )
    np.testing.assert_allclose(f.distance_mm[win], np.angle(z) * k, atol=2e-3)
    np.testing.assert_allclose(f.amplitude[win], np.abs(z), rtol=1e-9)
    centre = f.distance_mm[100, 120]
    assert 2800.0 < centre < plain.distance_mm[100, 120]
    assert centre < 2850.0  # the glint (~900 counts) outshines the plate (~30)
    # pixels the glint does not light are the frame's own
    far = np.ones(cam.shape, bool)
    far[80:121, 100:141] = False
    assert np.array_equal(f.gray[far], plain.gray[far])


def test_a_glints_pixels_carry_the_sensors_noise():
    cam = CameraModel()
    sensor = SensorModel(ambient_lux=0.0)
    gl = _glint(cam, (160.0, 120.0), 4000.0, 1.0, 800.0)
    frame = render_frame(cam, EMPTY, AWAY, sensor, np.random.default_rng(0))
    reads = [render_glints(frame, gl, cam, sensor, np.random.default_rng(s)) for s in range(300)]
    d = np.array([r.distance_mm[120, 160] for r in reads])
    g = np.array([r.gray[120, 160] for r in reads], float)
    a = reads[0].amplitude[120, 160]
    assert np.std(d) == pytest.approx(sensor.distance_sigma_mm(a, 0.0), rel=0.15)
    assert np.mean(d) == pytest.approx(4000.0, abs=3 * float(np.std(d)) / 300**0.5 + 0.1)
    assert np.std(g) == pytest.approx(np.sqrt(a), rel=0.15)


def test_a_glint_at_full_scale_saturates_with_no_distance():
    cam = CameraModel()
    sensor = SensorModel(noise=False, ambient_lux=0.0)
    f = _alone(cam, _glint(cam, (60.0, 60.0), 2000.0, 1.0, 9000.0), sensor)
    assert f.gray[60, 60] == 4095 and np.isnan(f.distance_mm[60, 60])
    edge = (f.gray > 100) & (f.gray < 4095)
    assert edge.any() and np.isfinite(f.distance_mm[edge]).all()


def test_drawn_glints_are_in_and_around_the_target_at_its_range_and_seen():
    cam, cat = CameraModel(), paper_target()
    scene = TargetScene(cat)
    rng = np.random.default_rng(5)
    from tofpose.sim.randomise import draw_pose

    for range_m in (3.0, 8.0):
        for _ in range(5):
            T = draw_pose(range_m, rng, cam)
            g = draw_glints(rng, cam, scene, T)
            assert len(g) == 15
            assert np.all(np.abs(g.range_mm - np.linalg.norm(T.t_mm)) <= 250.0)
            assert np.all((g.sigma_px >= 0.5) & (g.sigma_px <= 1.6))
            assert np.all((g.peak_counts >= 400.0) & (g.peak_counts <= 2500.0))
            centre, half = target_image_box(cam, cat, T)
            uv = cam.project(g.positions_mm)
            assert np.all(np.abs(uv - centre) <= 1.5 * half + 1e-9)
            assert np.all((uv >= -0.5) & (uv <= [cam.width - 0.5, cam.height - 0.5]))
            # none behind the target: nothing nearer along its ray
            d_hit, _, _ = scene.in_camera(T).raycast(g.positions_mm / g.range_mm[:, None])
            assert np.all(g.range_mm <= d_hit)


def test_glints_name_their_bad_input():
    p = np.array([[0.0, 0.0, 1000.0]])
    cases = [
        (dict(positions_mm=p, sigma_px=[1.0, 1.0], peak_counts=[5.0]), "differ in number"),
        (dict(positions_mm=-p, sigma_px=[1.0], peak_counts=[5.0]), "in front of the camera"),
        (dict(positions_mm=p, sigma_px=[0.0], peak_counts=[5.0]), "sigma_px"),
        (dict(positions_mm=p, sigma_px=[1.0], peak_counts=[-5.0]), "peak_counts"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            Glints(**kwargs)
    cam = CameraModel()
    gl = Glints(p, [1.0], [5.0])
    frame = render_frame(cam, EMPTY, AWAY, SensorModel(noise=False))
    with pytest.raises(ValueError, match="systematic"):
        render_glints(frame, gl, cam, SensorModel(noise=False, systematic=SystematicErrors()))
    with pytest.raises(ValueError, match="Generator"):
        render_glints(frame, gl, cam, SensorModel())
