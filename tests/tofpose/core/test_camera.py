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
