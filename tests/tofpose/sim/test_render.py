import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.sim.render import SPEED_OF_LIGHT_MM_S, SensorModel, combine_subframes, render_frame
from tofpose.sim.scene import FIRST_DISC, PLATE, TargetScene


def test_reflector_centre_and_size_follow_the_pinhole_model():
    cam, cat = CameraModel(), paper_target()
    T = facing_pose(2000.0, offset_mm=(10.0, 20.0))
    f = render(T, noise=False)
    centres = T.apply(cat.positions_mm)
    uv = cam.project(centres)
    for k in range(len(cat)):
        m = f.surface_id == FIRST_DISC + k
        if not m.any():
            continue
        rows, cols = np.nonzero(m)
        # pixel-centre sampling quantises the disc: tolerance shrinks with its area
        tol = max(0.05, 1.5 / np.sqrt(m.sum()))
        np.testing.assert_allclose([cols.mean(), rows.mean()], uv[k], atol=tol)
        expected_area = np.pi * (cam.fx * cat.diameters_mm[k] / 2 / centres[k, 2]) ** 2
        assert m.sum() == pytest.approx(expected_area, rel=0.1)


def test_noiseless_distance_is_exact_ray_intersection():
    cam = CameraModel()
    T = facing_pose(1800.0, 10, -8, 5)
    f = render(T, noise=False, sensor=SensorModel(noise=False, supersampling=1))
    n, p0 = T.R[:, 2], T.t_mm
    e = cam.pixel_bearings()
    plate = f.surface_id == PLATE
    s = (p0 @ n) / (e[plate] @ n)  # exact ray-plane distance
    np.testing.assert_allclose(f.distance_mm[plate], s, rtol=1e-6)
    disc = f.surface_id == FIRST_DISC + 5
    c = T.apply(paper_target().positions_mm[5])
    np.testing.assert_allclose(f.distance_mm[disc], (c @ n) / (e[disc] @ n), rtol=1e-6)


@pytest.mark.parametrize("distance_mm", [1500.0, 6000.0])
@pytest.mark.parametrize("lux", [1000.0, 10000.0])
def test_distance_noise_matches_cw_tof_model(distance_mm, lux):
    sensor = SensorModel(ambient_lux=lux, supersampling=1)
    T = facing_pose(distance_mm)
    frames = [render(T, seed=s, sensor=sensor) for s in range(60)]
    f0 = frames[0]
    stack = np.stack([f.distance_mm for f in frames])
    interior = (f0.surface_id >= FIRST_DISC) & np.isfinite(stack).all(axis=0)
    # interior pixels only: their 3x3 neighbourhood is the same disc
    import cv2

    same = cv2.erode((f0.surface_id >= FIRST_DISC).astype(np.uint8), np.ones((3, 3))) > 0
    sel = interior & same
    assert sel.sum() >= 4
    emp = stack[:, sel].std(axis=0, ddof=1)
    model = sensor.distance_sigma_mm(f0.amplitude[sel], f0.background[sel])
    assert np.median(emp / model) == pytest.approx(1.0, abs=0.1)


def test_edge_pixel_reads_between_the_two_surfaces():
    T = facing_pose(1500.0)
    f = render(T, noise=False)
    import cv2

    disc = (f.surface_id == FIRST_DISC + 5).astype(np.uint8)
    ring = (cv2.dilate(disc, np.ones((3, 3))) > 0) & (disc == 0) & (f.surface_id == PLATE)
    d_disc = np.nanmedian(f.distance_mm[disc > 0])
    d_plate = np.nanmedian(f.distance_mm[ring])
    mixed = [v for v in f.true_distance_mm[ring] if d_disc + 1 < v < d_plate - 1]
    assert len(mixed) > 0, "no flying pixel between reflector and plate"


def test_phase_wraps_at_the_unambiguous_range():
    sensor = SensorModel(modulation_frequency_hz=20e6, noise=False, supersampling=1)
    amb = SPEED_OF_LIGHT_MM_S / 2 / 20e6
    assert sensor.unambiguous_range_mm == pytest.approx(7494.8, abs=0.1)
    T = facing_pose(amb + 500.0)
    f = render(T, sensor=sensor, noise=False)
    plate = f.surface_id == FIRST_DISC + 5
    true = np.linalg.norm(T.apply(paper_target().positions_mm[5]))
    np.testing.assert_allclose(np.median(f.distance_mm[plate]), true - amb, atol=1.0)


def test_same_seed_same_frames_and_saturation_flags():
    T = facing_pose(2000.0)
    a, b = render(T, seed=7), render(T, seed=7)
    np.testing.assert_array_equal(a.gray, b.gray)
    np.testing.assert_array_equal(a.distance_mm, b.distance_mm)
    hot = render(T, sensor=SensorModel(auto_exposure=False, integration_time_us=4000.0), seed=1)
    sat = hot.gray == 4095
    assert sat.any() and np.isnan(hot.distance_mm[sat]).all()


def test_target_behind_camera_is_an_error():
    T = RigidTransform(np.eye(3), np.array([0.0, 0.0, -500.0]))
    with pytest.raises(ValueError, match="behind the camera"):
        render(T, noise=False, scene=TargetScene())


# -- motion artefacts: the four phase sub-frames see different scenes ------------------
def test_four_equal_subframes_are_the_static_frame():
    T = facing_pose(2500.0, 3, -4, 10)
    sensor = SensorModel(noise=False)
    cam, scene = CameraModel(), TargetScene(paper_target())
    static = render_frame(cam, scene, T, sensor)
    moving = render_frame(cam, scene, T, sensor, subframe_poses=[T, T, T, T])
    np.testing.assert_array_equal(moving.gray, static.gray)
    np.testing.assert_allclose(moving.distance_mm, static.distance_mm, rtol=1e-12, equal_nan=True)


def test_subframe_combination_is_the_four_phase_estimator():
    """Sub-frames 0 and 2 give the real part, 1 and 3 the imaginary part: a pixel that
    sees phase phi_a in samples 0 and 2 and phi_b in 1 and 3 reads cos(phi_a) + j sin(phi_b);
    one that changes surface halfway reads the mean of the two phasors."""
    a, pa, pb = 100.0, 0.3, 1.2
    z = np.zeros((1, 1))

    def sub(phi):
        return (np.full((1, 1), a * np.cos(phi)), np.full((1, 1), a * np.sin(phi)), z)

    re, im, _ = combine_subframes([sub(pa), sub(pb), sub(pa), sub(pb)])
    assert (re[0, 0], im[0, 0]) == pytest.approx((a * np.cos(pa), a * np.sin(pb)))
    re, im, _ = combine_subframes([sub(pa), sub(pa), sub(pb), sub(pb)])
    mean = 0.5 * (np.exp(1j * pa) + np.exp(1j * pb)) * a
    assert (re[0, 0], im[0, 0]) == pytest.approx((mean.real, mean.imag))
    with pytest.raises(ValueError, match="4 sub-frames"):
        combine_subframes([sub(pa)] * 3)


def test_a_slewing_table_smears_edges_along_the_motion():
    """Sideways motion of 2 px per sub-frame: pixels at the leading and trailing edges of
    markers and plate read distances that belong to no surface (the four phase samples saw
    different ones); edges across the motion (top, bottom) stay clean; inside a surface
    nothing changes."""
    cam, scene = CameraModel(), TargetScene(paper_target())
    sensor = SensorModel(noise=False, supersampling=1)
    step_mm = 2.0 * 2500.0 / cam.fx  # 2 px at 2.5 m
    poses = [facing_pose(2500.0, offset_mm=(k * step_mm, 0.0)) for k in range(4)]
    moving = render_frame(cam, scene, poses[0], sensor, subframe_poses=poses)
    static = render_frame(cam, scene, poses[0], sensor)
    bad = ~np.isclose(moving.distance_mm, static.distance_mm, atol=5.0, equal_nan=True)
    rows, cols = np.nonzero(bad)
    assert len(rows) > 50
    sid = static.surface_id
    h, w = sid.shape

    def edge_in_row(r, c):  # a surface boundary within the 6 px swept sideways
        window = sid[r, max(c - 7, 0) : min(c + 8, w)]
        return bool((window != window[0]).any())

    assert all(edge_in_row(r, c) for r, c in zip(rows, cols, strict=True))
    markers = sid >= FIRST_DISC
    hit_markers = {int(sid[r, c]) for r, c in zip(rows, cols, strict=True) if markers[r, c]}
    assert len(hit_markers) >= 6  # the markers' own edge pixels are among them


def test_saturation_is_the_cameras_full_scale():
    """The same over-exposed scene clips at 4095 on the default camera and at the full
    scale of a camera that states another; the clipped pixels have no distance."""
    import numpy as np

    from tofpose.core.camera import CameraModel
    from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel, render_frame
    from tofpose.sim.scene import TargetScene

    T = RigidTransform(rotation_from_euler_deg(0, 0, 5) @ R_FACING, np.array([0, 0, 2000.0]))
    hot = SensorModel(auto_exposure=False, integration_time_us=4000.0, noise=False)
    for full_scale in (4095.0, 1000.0):
        f = render_frame(CameraModel(full_scale_counts=full_scale), TargetScene(), T, hot)
        clipped = f.gray >= full_scale
        assert clipped.any() and f.gray.max() == full_scale
        assert np.isnan(f.distance_mm[clipped]).all()
