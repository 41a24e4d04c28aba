"""Settings from TOFPOSE_* variables; loopback detection; token storage."""

from __future__ import annotations

import os
import stat

import pytest
from pydantic import ValidationError

from backend.auth import load_or_create_token, token_matches
from backend.settings import Settings, is_loopback_host, visa_resource


def test_environment_variables_are_read(monkeypatch, tmp_path):
    monkeypatch.setenv("TOFPOSE_PORT", "9123")
    monkeypatch.setenv("TOFPOSE_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("TOFPOSE_API_TOKEN", "from-env")
    monkeypatch.setenv("TOFPOSE_CAMERA", "replay:/x.h5")
    s = Settings()
    assert s.port == 9123 and s.api_token.get_secret_value() == "from-env"
    assert s.camera == "replay:/x.h5"
    assert s.resolved_database_url == f"sqlite:///{tmp_path.resolve() / 'tofpose.db'}"
    assert "from-env" not in repr(s)  # the token is a secret


def test_defaults_bind_loopback_with_open_reads():
    s = Settings()
    assert (s.host, s.port) == ("127.0.0.1", 8000) and s.reads_are_open


@pytest.mark.parametrize(
    ("host", "loop"),
    [
        ("127.0.0.1", True),
        ("127.3.2.1", True),
        ("::1", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("192.168.1.5", False),
        ("lab-pc", False),
    ],
)
def test_loopback_detection(host, loop):
    assert is_loopback_host(host) is loop
    assert Settings(host=host).reads_are_open is loop


@pytest.mark.parametrize(
    "kw",
    [
        {"camera": "usb"},
        {"camera": "replay:"},
        {"motion": "acutrol"},
        {"camera": "tofcam660:"},
        {"camera": "tofcam660:camera.lab"},
        {"motion": "scpi:"},
        {"motion": "scpi:host"},
        {"motion": "scpi:host:99999"},
        {"port": 70000},
        {"frame_rate_hz": 0},
    ],
)
def test_bad_settings_are_named(kw):
    with pytest.raises(ValidationError) as exc:
        Settings(**kw)
    assert next(iter(kw)) in str(exc.value)


def test_token_generated_once_private_and_reused(tmp_path):
    t1, created = load_or_create_token(tmp_path, None)
    assert created and len(t1) >= 40
    mode = stat.S_IMODE(os.stat(tmp_path / "api_token").st_mode)
    assert mode == 0o600
    assert load_or_create_token(tmp_path, None) == (t1, False)
    assert load_or_create_token(tmp_path, "configured") == ("configured", False)
    assert token_matches(t1, t1) and not token_matches(t1, t1[:-1]) and not token_matches(t1, None)


@pytest.mark.parametrize(
    ("motion", "resource"),
    [
        ("scpi:127.0.0.1:5025", "TCPIP::127.0.0.1::5025::SOCKET"),
        ("scpi:table.lab:5025", "TCPIP::table.lab::5025::SOCKET"),
        ("scpi:GPIB0::14::INSTR", "GPIB0::14::INSTR"),
        ("scpi:ASRL/dev/ttyUSB0::INSTR", "ASRL/dev/ttyUSB0::INSTR"),
    ],
)
def test_scpi_motion_specs_name_a_visa_resource(motion, resource):
    assert Settings(motion=motion).motion == motion
    assert visa_resource(motion) == resource


def test_the_filter_model_and_its_jerk_come_from_the_environment(monkeypatch):
    import math

    from backend.app import _filter_config

    s = Settings()
    cfg = _filter_config(s)  # the default: constant angular acceleration, (30 deg)^2/s^5
    assert cfg.n_states == 18 and cfg.angular_jerk_psd == pytest.approx(math.radians(30) ** 2)
    monkeypatch.setenv("TOFPOSE_FILTER_JERK_DEG", "60")
    assert _filter_config(Settings()).angular_jerk_psd == pytest.approx(math.radians(60) ** 2)
    monkeypatch.setenv("TOFPOSE_FILTER_MODEL", "twist")
    assert _filter_config(Settings()).n_states == 12
    monkeypatch.setenv("TOFPOSE_FILTER_MODEL", "kalman")
    with pytest.raises(ValidationError, match="filter_model"):
        Settings()
