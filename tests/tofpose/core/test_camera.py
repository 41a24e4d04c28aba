import numpy as np
import pytest

from tofpose.core.camera import CameraModel


def test_epc660_defaults_match_paper_fov():
    cam = CameraModel.epc660()
    hfov = 2 * np.degrees(np.arctan(cam.width / 2 / cam.fx))
    vfov = 2 * np.degrees(np.arctan(cam.height / 2 / cam.fy))
    assert hfov == pytest.approx(52.4, abs=0.1)
    assert vfov == pytest.approx(40.6, abs=0.1)


@pytest.mark.parametrize("dist", [(0, 0, 0, 0, 0), (-0.2, 0.05, 0.001, -0.002, 0.0)])
def test_project_back_project_round_trip(dist):
    cam = CameraModel(dist=dist)
    rng = np.random.default_rng(1)
    p = np.column_stack(
        (rng.uniform(-800, 800, 50), rng.uniform(-600, 600, 50), rng.uniform(1000, 9000, 50))
    )
    uv = cam.project(p)
    back = cam.back_project(uv, np.linalg.norm(p, axis=1))
    np.testing.assert_allclose(back, p, atol=1e-3)


def test_bearing_is_eq8_unit_vector():
    cam = CameraModel()
    e = cam.bearings(np.array([[cam.cx, cam.cy], [0.0, 0.0]]))
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0)
    np.testing.assert_allclose(e[0], [0, 0, 1])
    u = np.array([(0 - cam.cx) / cam.fx, (0 - cam.cy) / cam.fy, 1.0])
    np.testing.assert_allclose(e[1], u / np.linalg.norm(u))


def test_project_behind_camera_raises():
    with pytest.raises(ValueError, match="behind the camera"):
        CameraModel().project(np.array([[0.0, 0.0, -1.0]]))


def test_json_round_trip_and_errors():
    cam = CameraModel(fx=300.0, dist=(0.1, 0, 0, 0, 0), name="x")
    assert CameraModel.from_json(cam.to_json()) == cam
    with pytest.raises(ValueError, match="missing fx"):
        CameraModel.from_dict({"width": 3, "height": 3, "fy": 1, "cx": 1, "cy": 1})
    with pytest.raises(ValueError, match="not valid JSON"):
        CameraModel.from_json("{")
    with pytest.raises(ValueError, match="5 coefficients"):
        CameraModel(dist=(0, 0))


def test_full_scale_and_modulation_travel_through_json_and_default_for_old_files():
    cam = CameraModel(full_scale_counts=65535.0, modulation_frequency_hz=20e6, name="other")
    back = CameraModel.from_json(cam.to_json())
    assert (back.full_scale_counts, back.modulation_frequency_hz) == (65535.0, 20e6)
    old = {
        k: v
        for k, v in cam.to_dict().items()
        if k not in ("full_scale_counts", "modulation_frequency_hz")
    }
    assert CameraModel.from_dict(old).full_scale_counts == 4095.0
    assert CameraModel.from_dict(old).modulation_frequency_hz == 6.0e6
    with pytest.raises(ValueError, match="full_scale_counts must be positive"):
        CameraModel(full_scale_counts=0.0)


def test_the_device_fields_travel_through_json_and_default_to_the_epc660s():
    cam = CameraModel(
        unwrapped_range_mm=3860.0,
        count_scale=16.0,
        distance_kind="z",
        depth_unit_mm=0.25,
        depth_invalid_code=65535,
        depth_max_valid_code=65534,
    )
    assert CameraModel.from_json(cam.to_json()) == cam
    assert cam.unambiguous_range_mm == 3860.0
    old = {k: CameraModel().to_dict()[k] for k in ("width", "height", "fx", "fy", "cx", "cy")}
    back = CameraModel.from_dict(old)
    assert back == CameraModel(name="")
    assert (back.count_scale, back.distance_kind, back.depth_unit_mm) == (1.0, "radial", 1.0)
    assert (back.depth_invalid_code, back.depth_max_valid_code) == (0, 63999)
    assert "unwrapped_range_mm" not in CameraModel().to_dict()  # single frequency: c / (2 f)
    assert CameraModel(modulation_frequency_hz=12e6).unambiguous_range_mm == pytest.approx(
        299_792_458_000.0 / (2 * 12e6)
    )
    with pytest.raises(ValueError, match="distance_kind must be one of radial, z"):
        CameraModel(distance_kind="depth")  # type: ignore[arg-type]


def test_the_focal_length_sigma_travels_through_json_and_is_exact_when_not_stated():
    cam = CameraModel(focal_length_sigma_rel=0.002)
    assert CameraModel.from_json(cam.to_json()).focal_length_sigma_rel == 0.002
    old = {k: v for k, v in cam.to_dict().items() if k != "focal_length_sigma_rel"}
    assert CameraModel.from_dict(old).focal_length_sigma_rel == 0.0
    for bad in (-0.001, 0.1, float("nan")):
        with pytest.raises(ValueError, match="focal_length_sigma_rel must be in"):
            CameraModel(focal_length_sigma_rel=bad)
