"""z depth <-> radial distance per pixel, and a device's raw codes <-> the pipeline's
distance image (``tofpose.core.depth``), against geometry computed independently."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile
from tofpose.core.depth import decode_depth, encode_depth, radial_from_z, z_from_radial

DISTORTED = CameraModel(dist=(-0.2, 0.05, 0.001, -0.002, 0.0))


def _plane_truth(camera: CameraModel, z0_mm: float) -> np.ndarray:
    """Radial distance (H, W) of a fronto-parallel plane at z0 seen by ``camera``, from
    OpenCV's undistortion of the pixel centres (not through CameraModel's bearings)."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(np.float64)
    uv = np.column_stack((u.ravel(), v.ravel())).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(uv, camera.K, camera.dist_array, criteria=(3, 200, 1e-12))
    xy = xy.reshape(camera.height, camera.width, 2)
    return z0_mm * np.sqrt(1.0 + xy[..., 0] ** 2 + xy[..., 1] ** 2)


@pytest.mark.parametrize("camera", [CameraModel(), DISTORTED, load_profile("azure-kinect-nfov")])
def test_a_plane_at_constant_z_reads_its_radial_distance_through_each_pixels_ray(camera):
    z = np.full(camera.shape, 2000.0, np.float32)
    rho = radial_from_z(z, camera)
    # (the camera undistorts as OpenCV does by default: to ~3e-6 of the converged ray)
    np.testing.assert_allclose(rho, _plane_truth(camera, 2000.0), rtol=1e-5)
    assert rho.dtype == np.float32
    # at the principal point the two agree; towards the corners radial grows
    cu, cv = int(camera.cx), int(camera.cy)
    assert rho[cv, cu] == pytest.approx(2000.0, rel=1e-5)
    assert rho[0, 0] > 2000.0 * 1.1
    np.testing.assert_allclose(z_from_radial(rho, camera), z, rtol=1e-6)


def test_the_paper_cameras_corner_reads_15_percent_nearer_as_z():
    camera = CameraModel()
    rho = np.full(camera.shape, 5000.0, np.float32)
    z = z_from_radial(rho, camera)
    e_z = 1.0 / np.sqrt(1 + (159.5 / 325.0) ** 2 + (119.5 / 325.0) ** 2)
    assert z[0, 0] == pytest.approx(5000.0 * e_z, rel=1e-6)
    assert 1 - e_z == pytest.approx(0.15, abs=0.005)


def test_a_stack_of_frames_converts_frame_by_frame():
    camera = CameraModel()
    z = np.stack([np.full(camera.shape, v, np.float32) for v in (1000.0, 2000.0, 3000.0)])
    rho = radial_from_z(z, camera)
    assert rho.shape == (3, 240, 320)
    for k in range(3):
        np.testing.assert_array_equal(rho[k], radial_from_z(z[k], camera))
    assert radial_from_z(z[:0], camera).shape == (0, 240, 320)


def test_invalid_pixels_stay_invalid_both_ways():
    camera = CameraModel()
    d = np.full(camera.shape, 3000.0, np.float32)
    d[10, 20] = np.nan
    for out in (radial_from_z(d, camera), z_from_radial(d, camera)):
        assert np.isnan(out[10, 20]) and np.isfinite(out).sum() == d.size - 1


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda c: radial_from_z(np.zeros((240, 321)), c), r"z-depth image has shape \(240, 321\)"),
        (lambda c: z_from_radial(np.zeros((10, 10)), c), r"distance image has shape \(10, 10\)"),
        (lambda c: decode_depth(np.zeros((240, 320), bool), c), "must be numbers"),
        (
            lambda c: encode_depth(np.zeros((240, 320)), c, dtype=np.uint8),
            "uint8 cannot hold the camera's codes",
        ),
    ],
)
def test_bad_images_are_named(call, message):
    with pytest.raises(ValueError, match=message):
        call(CameraModel())


def test_azure_kinect_codes_are_z_mm_with_zero_invalid():
    camera = load_profile("azure-kinect-nfov")
    raw = np.full(camera.shape, 1500, np.uint16)
    raw[0, :] = 0
    d = decode_depth(raw, camera)
    assert np.isnan(d[0]).all()
    truth = _plane_truth(camera, 1500.0)
    np.testing.assert_allclose(d[1:], truth[1:], rtol=2e-6)


def test_ahat_codes_from_4090_on_are_invalid_and_its_distance_is_radial():
    camera = load_profile("hololens2-ahat")
    raw = np.full(camera.shape, 999, np.uint16)
    raw[5, 5], raw[6, 6], raw[7, 7] = 4089, 4090, 0
    d = decode_depth(raw, camera)
    assert d[0, 0] == 999.0 and d[5, 5] == 4089.0  # radial: no conversion
    assert np.isnan(d[6, 6]) and np.isnan(d[7, 7])
    assert np.isfinite(d).sum() == d.size - 2


def test_float_depth_in_metres_reads_with_its_unit():
    """A ROS 32FC1 depth image: z in metres, NaN (or 0) where invalid."""
    camera = replace(CameraModel(), distance_kind="z", depth_unit_mm=1000.0)
    raw = np.full(camera.shape, 2.0, np.float32)
    raw[0, 0], raw[0, 1] = np.nan, 0.0
    d = decode_depth(raw, camera)
    assert np.isnan(d[0, :2]).all()
    np.testing.assert_allclose(d[1:], _plane_truth(camera, 2000.0)[1:], rtol=2e-6)


@pytest.mark.parametrize("name", ["tofcam660", "azure-kinect-nfov", "hololens2-ahat"])
def test_encode_then_decode_gives_the_distance_back_to_the_code_step(name):
    camera = load_profile(name)
    rng = np.random.default_rng(4)
    rho = rng.uniform(300.0, 900.0, camera.shape).astype(np.float32)
    rho[3, 4] = np.nan
    raw = encode_depth(rho, camera)
    assert raw.dtype == np.uint16 and raw[3, 4] == camera.depth_invalid_code
    back = decode_depth(raw, camera)
    assert np.isnan(back[3, 4])
    e_z = camera.pixel_bearings()[:, :, 2]
    step = 0.5 * camera.depth_unit_mm / (e_z if camera.distance_kind == "z" else np.ones_like(e_z))
    ok = np.isfinite(rho)
    assert np.all(np.abs(back - rho)[ok] <= step[ok] + 1e-3)
    # a float encoding keeps the fraction
    exact = decode_depth(encode_depth(rho, camera, dtype=np.float64), camera)
    np.testing.assert_allclose(exact[ok], rho[ok], rtol=1e-6)


def test_distances_beyond_the_largest_code_encode_as_invalid():
    camera = load_profile("hololens2-ahat")
    rho = np.full(camera.shape, 5000.0)
    assert np.all(encode_depth(rho, camera) == camera.depth_invalid_code)
