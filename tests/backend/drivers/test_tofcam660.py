"""The TOFcam-660 driver (around ESPROS's client) through the shipped emulator: frames,
codes, the same pose as the simulator directly, auto exposure, link loss."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from backend.drivers.base import CameraError, CameraSettings
from backend.drivers.sim import make_sim_world
from backend.drivers.tofcam660 import (
    TofCam660Driver,
    decode_distance_amplitude,
    next_integration_time_us,
)
from backend.emulators.tofcam660 import TofCam660Emulator
from tests.backend.conftest import wait_for
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_angle_deg
from tofpose.pipeline import PosePipeline

ADDRESS = "127.0.0.3"
FIXED = CameraSettings(integration_time_us=300.0, auto_exposure=False, frame_rate_hz=60.0)


@pytest.fixture
def world():
    w = make_sim_world(start_rail_mm=13000.0)
    w.set_sensor(noise=False)
    return w


@pytest.fixture
def emu(world):
    with TofCam660Emulator(world, ADDRESS) as e:
        yield e


def test_same_pose_as_the_simulator_directly(world, emu):
    drv = TofCam660Driver(ADDRESS, settings=FIXED)
    try:
        frame = drv.read(2.0)
    finally:
        drv.close()
    _, direct, T_lab, T_true, _ = world.capture()
    np.testing.assert_array_equal(frame.gray, direct.gray)
    valid = np.isfinite(direct.distance_mm)
    np.testing.assert_array_equal(np.isfinite(frame.distance_mm), valid)
    np.testing.assert_array_equal(frame.distance_mm[valid], np.rint(direct.distance_mm[valid]))
    pipe = PosePipeline(drv.model, paper_target())
    via_camera = pipe.process(frame.gray, frame.distance_mm)
    quantised = np.where(valid, np.rint(direct.distance_mm), np.nan).astype(np.float32)
    same_input = PosePipeline(drv.model, paper_target()).process(direct.gray, quantised)
    unquantised = PosePipeline(drv.model, paper_target()).process(direct.gray, direct.distance_mm)
    assert via_camera.ok and via_camera.n_matched == 8
    np.testing.assert_allclose(via_camera.t_mm, same_input.t_mm, atol=1e-9)
    np.testing.assert_allclose(via_camera.R, same_input.R, atol=1e-12)
    # against the simulator's float distances, only the camera's 1 mm steps differ
    assert np.linalg.norm(via_camera.t_mm - unquantised.t_mm) < 0.5
    assert rotation_angle_deg(via_camera.R, unquantised.R) < 0.05
    assert np.linalg.norm(via_camera.t_mm - T_true.t_mm) < 5.0


def test_roi_moves_the_principal_point(emu):
    drv = TofCam660Driver(ADDRESS, settings=FIXED, roi=(40, 20, 280, 220))
    try:
        frame = drv.read(2.0)
    finally:
        drv.close()
    assert frame.gray.shape == (200, 240) == drv.model.shape
    assert (drv.model.cx, drv.model.cy) == (159.5 - 40, 119.5 - 20)


def test_invalid_codes_become_nan_and_saturation_full_scale():
    dist = np.array([[1500, 64001, 64002, 64003]], np.uint16)
    amp = np.array([[3000, 40, 64002, 64003]], np.uint16)
    gray, d, n_sat = decode_distance_amplitude(dist, amp, full_scale_counts=2894)
    assert d[0, 0] == 1500 and np.isnan(d[0, 1:]).all()
    # saturated pixels become the brightest value of the frame (here the valid 3000)
    assert gray.tolist() == [[3000, 40, 3000, 3000]] and n_sat == 2


@pytest.mark.parametrize(
    ("current", "peak", "n_sat", "expected"),
    [
        (1000.0, 1736.4, 0, 1000.0),  # at the goal (0.6 x 2894): kept
        (1000.0, 868.2, 0, 2000.0),  # half the goal: doubled
        (1000.0, 100.0, 0, 2000.0),  # far below: at most x2 a step
        (1000.0, 2894.0, 3, 500.0),  # saturated: halved
        (3000.0, 100.0, 0, 4000.0),  # clamped to the camera's range
        (1.5, 2894.0, 1, 1.0),
    ],
)
def test_auto_exposure_step(current, peak, n_sat, expected):
    assert next_integration_time_us(current, peak, n_sat, 2894.0) == pytest.approx(
        expected, rel=1e-6
    )


def test_auto_exposure_leaves_saturation_within_a_few_frames(world, emu):
    settings = CameraSettings(integration_time_us=4000.0, auto_exposure=True, frame_rate_hz=60)
    drv = TofCam660Driver(ADDRESS, settings=settings)
    try:
        saturated = [drv.read(2.0).meta["saturated_px"] for _ in range(8)]
        last = drv.read(2.0)
    finally:
        drv.close()
    assert saturated[0] > 0  # 4 ms at 2 m saturates the reflectors
    assert last.meta["saturated_px"] == 0
    peak = last.gray[np.isfinite(last.distance_mm)].max()
    assert 0.6 * 2894 / 1.15 <= peak <= 0.6 * 2894 * 1.15 * 1.1
    assert world.bench.sensor.integration_time_us == last.meta["integration_time_us"]


def test_settings_are_clamped_and_sent_to_the_camera(world, emu):
    drv = TofCam660Driver(ADDRESS, settings=FIXED)
    try:
        applied = drv.apply_settings(
            CameraSettings(
                integration_time_us=9000.0, modulation_frequency_mhz=10.0, auto_exposure=False
            )
        )
        assert applied.integration_time_us == 4000.0
        assert applied.modulation_frequency_mhz == 12.0  # the nearest the camera has
        assert world.bench.sensor.modulation_frequency_hz == 12e6
        assert world.bench.sensor.integration_time_us == 4000.0
    finally:
        drv.close()


def test_dropped_link_mid_stream_then_reconnect(emu):
    drv = TofCam660Driver(ADDRESS, settings=FIXED, reconnect_backoff_s=(0.05, 0.2))
    try:
        first = drv.read(2.0).index
        emu.drop_clients()
        with pytest.raises(CameraError, match="127.0.0.3"):
            drv.read(2.0)
        assert drv.describe()["link"] == "down"
        frame = wait_for(lambda: _try_read(drv), 5.0, "frames after the reconnect")
        assert frame.index > first and drv.describe()["link"] == "up"
    finally:
        drv.close()


def test_a_lost_image_fails_that_frame_within_the_time_out_and_the_next_one_arrives(emu):
    """The UDP socket keeps its time-out across reads (the vendor's buffer flush would
    clear it, and a lost image then blocked the read and the server's shutdown)."""
    drv = TofCam660Driver(ADDRESS, settings=FIXED, io_timeout_s=0.5)
    try:
        first = drv.read(2.0).index
        emu.lose_images()
        t0 = time.monotonic()
        with pytest.raises(CameraError, match="image lost"):
            drv.read(2.0)
        assert time.monotonic() - t0 < 2.0
        assert drv.describe()["link"] == "up"  # the command link answered: still up
        emu.lose_images(False)
        assert drv.read(2.0).index > first
    finally:
        drv.close()


def _try_read(drv):
    try:
        return drv.read(1.0)
    except CameraError:
        return None


def test_absent_camera_is_an_error_naming_it_or_a_degraded_start():
    with pytest.raises(CameraError, match="127.0.0.4: cannot connect"):
        TofCam660Driver("127.0.0.4")
    drv = TofCam660Driver(
        "127.0.0.4", settings=FIXED, connect_now=False, reconnect_backoff_s=(0.05, 0.1)
    )
    try:
        with pytest.raises(CameraError, match="cannot connect"):
            drv.read(1.0)
        world = make_sim_world(start_rail_mm=13000.0)
        with TofCam660Emulator(world, "127.0.0.4"):  # the camera is switched on
            time.sleep(0.1)
            assert wait_for(lambda: _try_read(drv), 5.0, "the first frame").gray.shape == (
                240,
                320,
            )
    finally:
        drv.close()


def test_a_refused_setting_is_reported_naming_the_command(emu):
    with pytest.raises(CameraError, match=r"setup failed: .*refused command: SetRoi.*Error"):
        TofCam660Driver(ADDRESS, settings=FIXED, roi=(0, 10, 320, 200))  # rows not symmetric


def test_a_new_modulation_frequency_is_the_model_the_lab_camera_reports(world, emu):
    """The driver's model (what the live pipeline measures with) takes the frequency the
    camera applied: its distances now wrap at c / (2 f). Also through the lab's encoder
    wrapper (``EncoderReferencedCamera``, how ``build_devices`` hands the camera to the
    server beside a motion system), and only a new frequency makes a new model (the live
    loop rebuilds its pipeline on one)."""
    from backend.drivers.reference import EncoderReferencedCamera
    from backend.drivers.sim import SimMotion
    from tofpose.sim.bench import LabGeometry

    drv = TofCam660Driver(ADDRESS, settings=FIXED)
    lab = EncoderReferencedCamera(drv, SimMotion(world), LabGeometry())
    try:
        assert lab.model is drv.model and lab.model.modulation_frequency_hz == 6e6
        before = lab.model
        lab.apply_settings(replace(FIXED, frame_rate_hz=30.0))
        assert lab.model is before  # no new frequency, the same model
        lab.apply_settings(replace(FIXED, modulation_frequency_mhz=24.0))
        assert lab.model is drv.model and lab.model.modulation_frequency_hz == 24e6
        assert lab.model.unambiguous_range_mm == pytest.approx(6245.7, abs=0.1)
    finally:
        drv.close()
