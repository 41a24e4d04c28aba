"""Camera settings of a campaign request: checks against a camera's limits (each message
names the field, the value and what is allowed), sweeps, and the camera's identity."""

from __future__ import annotations

from backend.drivers.base import CameraLimits
from backend.drivers.sim import SimCamera, make_sim_world
from backend.drivers.tofcam660 import INTEGRATION_LIMITS_US, MODULATION_MHZ, TofCam660Driver
from backend.emulators.tofcam660 import CHIP, FIRMWARE, TofCam660Emulator
from backend.services.campaigns.camera_plan import (
    DEFAULT_LIMITS,
    camera_identity,
    camera_limits,
    plan_cameras,
    raw_recording_problems,
    setting_problems,
    with_sweep,
)

EPC660 = CameraLimits(integration_time_us=(1.0, 4000.0), modulation_frequencies_mhz=MODULATION_MHZ)


def test_a_discrete_camera_names_its_frequencies():
    (problem,) = setting_problems({"modulation_frequency_mhz": 7.0}, EPC660, "tofcam660", ["c"])
    assert problem == (
        ["c", "modulation_frequency_mhz"],
        "modulation_frequency_mhz 7 MHz is not one the 'tofcam660' camera supports: "
        "24, 12, 6, 3, 1.5, 0.75 MHz",
    )
    assert setting_problems({"modulation_frequency_mhz": 12.0}, EPC660, "tofcam660", []) == []


def test_limits_are_inclusive_and_a_replay_takes_none():
    for t, n in ((1.0, 0), (4000.0, 0), (0.5, 1), (4000.5, 1)):
        assert len(setting_problems({"integration_time_us": t}, EPC660, "x", [])) == n
    replay = CameraLimits(integration_time_us=(0.0, 0.0), settable=False)
    (problem,) = setting_problems({"integration_time_us": 100.0}, replay, "replay", ["b"])
    assert problem == (["b"], "the 'replay' camera's settings cannot be changed")
    assert setting_problems({}, replay, "replay", ["b"]) == []


def test_a_sweep_repeats_each_set_point_in_place():
    points, cams = with_sweep([{"yaw": 0.0}, {"yaw": 5.0}], {"integration_time_us": [100, 200]})
    assert points == [{"yaw": 0.0}, {"yaw": 0.0}, {"yaw": 5.0}, {"yaw": 5.0}]
    assert cams == [{"integration_time_us": t} for t in (100.0, 200.0, 100.0, 200.0)]


def test_a_bad_sweep_value_is_located_by_its_index_and_nothing_is_expanded():
    points, cams, problems = plan_cameras(
        [{"yaw": 0.0}], None, {"integration_time_us": [100, 9000]}, None, EPC660, "tofcam660"
    )
    assert points == [{"yaw": 0.0}] and cams == [{}]
    assert [loc for loc, _ in problems] == [["body", "camera_sweep", "integration_time_us", 1]]


def test_the_drivers_report_their_limits_and_the_tofcam660_its_chip(tmp_path):
    world = make_sim_world(start_rail_mm=13000.0)
    assert camera_limits(SimCamera(world)).integration_time_us == (10.0, 4000.0)
    assert camera_limits(object()) == DEFAULT_LIMITS
    with TofCam660Emulator(world, "127.0.0.6"):
        drv = TofCam660Driver("127.0.0.6")
        try:
            limits = camera_limits(drv)
            assert limits.integration_time_us == INTEGRATION_LIMITS_US
            assert limits.modulation_frequencies_mhz == MODULATION_MHZ
            info = drv.describe()
            assert info["serial"] == f"wafer {CHIP[0]} chip {CHIP[1]}"
            assert info["firmware"] == f"{FIRMWARE[0]}.{FIRMWARE[1]}"
            identity, problems = camera_identity(info, {"camera_serial": "typed"})
        finally:
            drv.close()
    assert identity["camera_serial"] == info["serial"] and identity["camera_model"] == info["model"]
    assert problems == [
        (
            ["body", "camera_serial"],
            f"camera_serial 'typed' was given, but the connected camera reports "
            f"{info['serial']!r}: leave it out to take the device's",
        )
    ]


def test_a_raw_recording_takes_one_modulation_frequency():
    """``raw_recording_problems``: one frequency (given everywhere, by the base, or the
    camera's own everywhere) is fine; two, or one given beside the camera's own, is one
    problem at ``record_raw``; nothing without ``record_raw``."""
    f12, f6 = {"modulation_frequency_mhz": 12.0}, {"modulation_frequency_mhz": 6.0}
    assert raw_recording_problems([f12, f12], None, True) == []
    assert raw_recording_problems([{}, {}], None, True) == []
    assert raw_recording_problems([{}, f12], f12, True) == []  # the base fills the gap
    assert raw_recording_problems([{"integration_time_us": 100.0}, {}], None, True) == []
    assert raw_recording_problems([f6, f12], None, False) == []
    [(loc, msg)] = raw_recording_problems([f6, f12], None, True)
    assert loc == ["body", "record_raw"] and "6 MHz, 12 MHz" in msg
    [(_, msg)] = raw_recording_problems([{}, f12], None, True)
    assert "12 MHz and the camera's own" in msg
    [(_, msg)] = raw_recording_problems([{}, f12], f6, True)
    assert "6 MHz, 12 MHz" in msg and "camera's own" not in msg
