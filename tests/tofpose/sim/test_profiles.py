"""The simulator renders any camera profile: its resolution and intrinsics, its count
scale and full scale, its modulation frequency and range; and the pipeline measures the
pose through each."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import facing_pose
from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile
from tofpose.core.catalog import paper_target
from tofpose.core.depth import decode_depth, encode_depth
from tofpose.pipeline import PosePipeline
from tofpose.sim.render import SensorModel, render_frame, sensor_for_camera
from tofpose.sim.scene import FIRST_DISC, NO_HIT, TargetScene

#: chi^2 with 6 degrees of freedom at p = 0.999
CHI2_6_999 = 22.46


def _device_frames(camera, T, *, n, seed, sensor=None):
    """n frames of pose T through ``camera`` as the device delivers them (raw distance
    codes), decoded as the pipeline takes them: (gray, radial distance) pairs."""
    sensor = sensor_for_camera(sensor or SensorModel(), camera)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        f = render_frame(camera, TargetScene(), T, sensor, rng)
        raw = encode_depth(f.distance_mm, camera)  # z mm codes on the Azure Kinect
        yield f.gray, decode_depth(raw, camera)


@pytest.mark.parametrize(
    ("name", "distance_mm"),
    [
        ("tofcam660", 2500.0),
        ("azure-kinect-nfov", 2500.0),
        ("tofcam660", 900.0),
        ("azure-kinect-nfov", 900.0),
        ("hololens2-ahat", 900.0),
    ],
)
def test_the_same_scene_through_each_profile_gives_the_pose_within_its_sigmas(name, distance_mm):
    """The same target pose rendered through two (at 0.9 m: three) cameras of different
    resolution, intrinsics, count scale, frequency and distance kind: the pipeline's
    pose is within its reported covariance of the truth on each (per axis within 4
    sigma, the 6-D error's chi^2 below its 99.9 % point)."""
    camera = load_profile(name)
    T = facing_pose(distance_mm, 2.0, -3.0, 10.0, offset_mm=(30.0, -20.0))
    pipe = PosePipeline(camera, paper_target())
    for gray, dist in _device_frames(camera, T, n=4, seed=3):
        assert gray.shape == camera.shape
        r = pipe.process(gray, dist)
        assert r.ok, r.reason
        assert len(r.matched) >= 6
        e = np.concatenate(
            (Rotation.from_matrix(r.R @ T.R.T).as_rotvec(), np.asarray(r.t_mm) - T.t_mm)
        )
        sigma = np.sqrt(np.diag(r.covariance))
        assert np.all(np.abs(e) < 4 * sigma), (e, sigma)
        assert e @ np.linalg.solve(r.covariance, e) < CHI2_6_999
        # and close in absolute terms (its sigmas are wide: seeds 0-7 reach 0.7 sigma)
        assert np.linalg.norm(e[3:]) < 2.0 and np.degrees(np.linalg.norm(e[:3])) < 0.15


def test_a_16_bit_camera_renders_16x_the_counts_and_clips_at_its_own_full_scale():
    """count_scale 16 and full scale 65535: the same radiometry (the same exposure) in
    16x the counts; saturation where the reference camera saturates."""
    T = facing_pose(2000.0, 0, 0, 5)
    ref = CameraModel()
    wide = replace(ref, count_scale=16.0, full_scale_counts=65535.0)
    hot = SensorModel(auto_exposure=False, integration_time_us=4000.0, noise=False)
    a = render_frame(ref, TargetScene(), T, hot)
    b = render_frame(wide, TargetScene(), T, hot)
    sat_a, sat_b = a.gray >= 4095, b.gray >= 65535
    assert sat_a.any() and b.gray.max() == 65535
    # 4095 counts = 65520 on the 16-bit scale: the 16x camera clips a little later
    assert np.all(sat_b <= sat_a) and sat_b.sum() >= 0.95 * sat_a.sum()
    assert np.isnan(b.distance_mm[sat_b]).all()
    lit = ~sat_a & (a.gray > 100)
    np.testing.assert_allclose(b.gray[lit], 16.0 * a.gray[lit], atol=8.0)
    auto = SensorModel(noise=False)
    assert render_frame(wide, TargetScene(), T, auto).integration_time_us == pytest.approx(
        render_frame(ref, TargetScene(), T, auto).integration_time_us, rel=1e-3
    )


def test_the_ahat_like_sensor_wraps_at_one_metre():
    camera = load_profile("hololens2-ahat")
    sensor = sensor_for_camera(SensorModel(noise=False, supersampling=1), camera)
    f = render_frame(camera, TargetScene(), facing_pose(1300.0), sensor)
    ok = np.isfinite(f.distance_mm) & (f.surface_id != NO_HIT)
    assert ok.sum() > 1000
    np.testing.assert_allclose(f.distance_mm[ok], np.mod(f.true_distance_mm[ok], 1000.0), atol=2e-3)
    assert np.nanmax(f.distance_mm) < 1000.0 < np.nanmin(f.true_distance_mm[ok])


def test_a_multi_frequency_camera_reads_its_mixed_pixels_unwrapped():
    """The Azure Kinect profile's 200 MHz phase wraps every 0.75 m, but the device
    unwraps to 3.86 m: a pixel on a marker's edge reads between marker and plate, not a
    period away."""
    camera = load_profile("azure-kinect-nfov")
    sensor = sensor_for_camera(SensorModel(noise=False), camera)
    T = facing_pose(2500.0, 0, 0, 5)
    f = render_frame(camera, TargetScene(), T, sensor)
    markers = f.surface_id >= FIRST_DISC
    near = markers | (np.abs(np.diff(markers.astype(int), axis=1, prepend=0)) > 0)
    d = f.distance_mm[near & np.isfinite(f.distance_mm)]
    assert d.size > 50
    # the markers stand 100-150 mm off a plate ~2.5 m away (up to ~2.8 m at the edges)
    assert np.all((d > 2200.0) & (d < 2900.0))


def test_the_azure_kinect_at_half_a_metre_needs_the_active_cap_scaled_to_its_frame():
    """At 0.5 m the markers in the Azure Kinect profile's view cover ~21 000 pixels: the
    EPC660's 12 000-pixel active cap cuts them into fragments (no pose); scaled to the
    640 x 576 frame (``config_for_camera``) the same frames give the pose."""
    from tofpose.config import PipelineConfig, config_for_camera

    camera = load_profile("azure-kinect-nfov")
    T = facing_pose(500.0, 2.0, -3.0, 10.0, offset_mm=(30.0, -20.0))
    frames = list(_device_frames(camera, T, n=2, seed=1))
    fixed = PosePipeline(camera, paper_target(), PipelineConfig())
    assert not any(fixed.process(g, d).ok for g, d in frames)
    config = config_for_camera(
        PipelineConfig(), width=camera.width, height=camera.height, count_scale=camera.count_scale
    )
    scaled = PosePipeline(camera, paper_target(), config)
    for g, d in frames:
        r = scaled.process(g, d)
        assert r.ok, r.reason
        assert np.linalg.norm(r.t_mm - T.t_mm) < 1.0
