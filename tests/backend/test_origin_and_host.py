"""Cross-site reads: Host checked against the served names (DNS rebinding), Origin on
the WebSocket (any page the operator visits must not read the live stream)."""

from __future__ import annotations

import pytest
from starlette.websockets import WebSocketDisconnect

from tests.backend.conftest import make_settings, running_app


@pytest.mark.parametrize(
    ("host_header", "status"),
    [
        ("testserver", 200),
        ("localhost:8000", 200),
        ("127.0.0.1:8000", 200),
        ("[::1]:8000", 200),
        ("evil.example", 400),
        ("evil.example:8000", 400),
        ("127.0.0.1.evil.example", 400),
    ],
)
def test_rest_answers_only_the_names_it_serves(client, host_header, status):
    r = client.get("/api/health", headers={"Host": host_header})
    assert r.status_code == status
    if status == 400:
        assert "host" in r.text.lower()


def test_extra_names_can_be_allowed_and_a_wildcard_bind_accepts_any(tmp_path):
    with running_app(make_settings(tmp_path / "a", allowed_hosts=["bench-pc.lab"])) as c:
        assert c.get("/api/health", headers={"Host": "bench-pc.lab:8000"}).status_code == 200
        assert c.get("/api/health", headers={"Host": "other.lab"}).status_code == 400
    s = make_settings(tmp_path / "b", host="0.0.0.0", allowed_hosts=[])
    assert s.trusted_hosts == ["*"]


def _hello(client, headers):
    with client.websocket_connect("/ws/live", headers=headers) as ws:
        return ws.receive_json()["type"]


@pytest.mark.parametrize(
    "origin", ["http://evil.example", "http://localhost:9999", "null", "file://"]
)
def test_a_cross_origin_websocket_is_refused(client, origin):
    with pytest.raises(WebSocketDisconnect) as exc:
        _hello(client, {"Origin": origin})
    assert exc.value.code == 1008


def test_same_origin_no_origin_and_allow_listed_origins_are_served(tmp_path):
    s = make_settings(tmp_path, allowed_origins=["http://localhost:5173"])
    with running_app(s) as c:
        assert _hello(c, {}) == "hello"  # a script: no Origin
        assert _hello(c, {"Origin": "http://testserver"}) == "hello"  # the dashboard
        assert _hello(c, {"Origin": "http://localhost:5173"}) == "hello"  # a dev server


def test_a_malformed_allowed_origin_is_a_settings_error(tmp_path):
    with pytest.raises(ValueError, match="allowed origin must look like"):
        make_settings(tmp_path, allowed_origins=["localhost:5173"])


def test_origins_and_hosts_come_from_comma_separated_variables(tmp_path, monkeypatch):
    monkeypatch.setenv("TOFPOSE_ALLOWED_HOSTS", "a.lab, b.lab")
    monkeypatch.setenv("TOFPOSE_ALLOWED_ORIGINS", "http://a.lab:5173")
    from backend.settings import Settings

    s = Settings(data_dir=tmp_path)
    assert s.allowed_hosts == ["a.lab", "b.lab"]
    assert s.allowed_origins == ["http://a.lab:5173"]
