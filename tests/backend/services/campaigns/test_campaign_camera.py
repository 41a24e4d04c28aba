"""CampaignCamera: per-set-point settings over the campaign's, and the camera's own
settings put back once, whatever way the campaign leaves."""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import replace

import pytest

from backend.drivers.base import CameraSettings
from backend.services.campaigns.campaign_camera import CampaignCamera


class _Camera:
    def __init__(self, refuse_us: float | None = None) -> None:
        self.settings = CameraSettings()  # auto exposure, 500 us, 6 MHz
        self.applied: list[CameraSettings] = []
        self.refuse_us = refuse_us

    def get_settings(self) -> CameraSettings:
        return self.settings

    def apply_settings(self, s: CameraSettings) -> CameraSettings:
        if s.integration_time_us == self.refuse_us:
            raise RuntimeError(f"{s.integration_time_us:g} us refused")
        self.settings = s
        self.applied.append(s)
        return s


class _Acquisition:
    """Runs submitted commands at once (the acquisition thread's part)."""

    def __init__(self, camera) -> None:
        self.camera = camera

    def submit(self, fn) -> Future:
        fut: Future = Future()
        try:
            fut.set_result(fn())
        except Exception as exc:
            fut.set_exception(exc)
        return fut


def test_setpoint_settings_go_over_the_campaigns_and_the_camera_gets_its_own_back():
    cam = _Camera()
    own = cam.settings
    cc = CampaignCamera(_Acquisition(cam))
    cc.begin({"modulation_frequency_mhz": 12.0})
    assert cc.expected_integration_us is None  # auto exposure still on
    s = cc.for_setpoint({"integration_time_us": 200.0})
    assert s == replace(
        own, modulation_frequency_mhz=12.0, integration_time_us=200.0, auto_exposure=False
    )
    assert cc.expected_integration_us == 200.0
    n = len(cam.applied)
    cc.for_setpoint({"integration_time_us": 200.0})  # unchanged: nothing sent
    assert len(cam.applied) == n
    assert cc.for_setpoint(None) == replace(own, modulation_frequency_mhz=12.0)  # the campaign's
    assert cc.restore() is None and cam.settings == own
    assert cc.restore() is None and cam.applied.count(own) == 1  # restored once


def test_a_campaign_that_fails_on_a_setting_still_restores_the_camera():
    cam = _Camera(refuse_us=300.0)
    own = cam.settings
    cc = CampaignCamera(_Acquisition(cam))
    cc.begin(None)
    cc.for_setpoint({"integration_time_us": 100.0})
    with pytest.raises(RuntimeError, match="300 us refused"):
        cc.for_setpoint({"integration_time_us": 300.0})
    assert cc.restore() is None and cam.settings == own


def test_a_restore_that_fails_says_why():
    cam = _Camera(refuse_us=500.0)  # the camera's own integration time: refused on the way back
    cc = CampaignCamera(_Acquisition(cam))
    cc.begin(None)
    cc.for_setpoint({"integration_time_us": 100.0})
    assert cc.restore() == "the camera's previous settings could not be restored: 500 us refused"
