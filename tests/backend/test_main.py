"""``tofpose serve``: the README's main command, end to end in a subprocess."""

from __future__ import annotations

from tests.backend.serve_process import ServeProcess
from tofpose.cli import main


def test_serve_starts_prints_urls_and_token_and_stops_cleanly(tmp_path):
    data = tmp_path / "data"
    with ServeProcess(data) as server:
        assert server.get_json("/api/pose/latest")["ok"]
        port = server.port
        server.stop()
    assert server.proc.returncode == 0, server.output
    out = server.output
    assert f"http://127.0.0.1:{port}/docs" in out
    assert f"ws://127.0.0.1:{port}/ws/live" in out
    assert f"sqlite:///{(data / 'tofpose.db').resolve()}" in out
    assert server.token in out and "generated now" in out


def test_the_token_is_printed_only_when_it_is_generated(tmp_path):
    """A second start on the same data directory names the token file, not the token."""
    data = tmp_path / "data"
    with ServeProcess(data) as first:
        token = first.token
    assert token in first.output
    with ServeProcess(data) as second:
        assert second.token == token
    assert token not in second.output
    assert str(data / "api_token") in second.output and "not printed" in second.output


def test_serve_refuses_bad_options_with_a_message(tmp_path, capsys):
    assert main(["serve", "--camera", "usb3", "--data-dir", str(tmp_path)]) == 2
    assert "camera must be 'sim', 'replay:PATH.h5' or 'tofcam660:ADDRESS'" in (
        capsys.readouterr().err
    )
    # a rate table that does not answer: its axes and limits come from it, so no start
    assert (
        main(["serve", "--motion", "scpi:127.0.0.1:9", "--data-dir", str(tmp_path), "--no-viser"])
        == 2
    )
    err = capsys.readouterr().err
    assert "cannot reach the rate-table controller at TCPIP::127.0.0.1::9::SOCKET" in err
    missing = tmp_path / "missing.h5"
    assert main(["serve", "--camera", f"replay:{missing}", "--data-dir", str(tmp_path)]) == 2
    assert "cannot replay" in capsys.readouterr().err


def test_serve_runs_the_3d_scene_on_its_own_port_and_no_viser_switches_it_off(tmp_path):
    import urllib.request

    with ServeProcess(tmp_path / "a") as server:  # ServeProcess passes --viser-port 0
        scene = server.get_json("/api/scene")
        assert scene["running"] and scene["port"] not in (None, 0, server.port)
        with urllib.request.urlopen(f"http://127.0.0.1:{scene['port']}/", timeout=5) as r:
            assert r.status == 200 and b"<html" in r.read(2000).lower()
        assert "viser on any free port (GET /api/scene names it)" in server.output
    with ServeProcess(tmp_path / "b", "--no-viser") as server:
        scene = server.get_json("/api/scene")
        assert not scene["running"] and "--no-viser" in scene["reason"]
        assert "3-D scene switched off" in server.output


KEY = "k3y-that-must-never-be-logged-0123456789abcdef"


def _send_the_key_everywhere(base_url: str, ws_url: str) -> None:
    """Requests that carry KEY in a header, in query strings (which the server refuses
    or ignores) and as the WebSocket subprotocol."""
    import httpx
    from websockets.exceptions import ConnectionClosed, InvalidStatus
    from websockets.sync.client import connect

    auth = {"Authorization": f"Bearer {KEY}"}
    assert httpx.get(f"{base_url}/api/motion?token={KEY}&x=1").status_code == 200
    assert httpx.post(f"{base_url}/api/motion/stop?api_key={KEY}", headers=auth).status_code == 200
    assert httpx.post(f"{base_url}/api/motion/stop?ticket={KEY}").status_code == 401
    try:
        with connect(f"{ws_url}?token={KEY}") as ws:
            ws.recv(timeout=10)
    except (InvalidStatus, ConnectionClosed, ConnectionError):
        pass  # refused: a key in the URL
    with connect(ws_url, subprotocols=["tofpose.bearer", f"tofpose.bearer.{KEY}"]) as ws:
        assert '"hello"' in ws.recv(timeout=10)


def test_no_key_reaches_the_logs_of_a_serve_run(tmp_path):
    """uvicorn's access log and its WebSocket lines print each URL with its query: the
    filter that ``tofpose serve`` installs redacts token/key/ticket values."""
    data = tmp_path / "data"
    with ServeProcess(data, env={"TOFPOSE_API_TOKEN": KEY}) as server:
        ws_url = server.base_url.replace("http://", "ws://") + "/ws/live"
        _send_the_key_everywhere(server.base_url, ws_url)
        server.stop()
    out = server.output
    assert KEY not in out
    assert "/api/motion?token=***&x=1" in out and "/api/motion/stop?api_key=***" in out
    assert "/api/motion/stop?ticket=***" in out and "/ws/live?token=***" in out
    assert "admin key from TOFPOSE_API_TOKEN (not printed)" in out


def test_no_key_reaches_the_apps_own_loggers(tmp_path, caplog):
    import logging

    from tests.backend.conftest import LiveServer, make_settings

    caplog.set_level(logging.DEBUG)
    with LiveServer(make_settings(tmp_path, api_token=KEY)) as srv:
        _send_the_key_everywhere(srv.base_url, srv.ws_url)
    # the test's own clients (websockets.client, httpx) log the headers they send at DEBUG:
    # theirs are not the server's logs
    clients = ("websockets", "httpx", "httpcore")
    server_side = [r for r in caplog.records if r.name.partition(".")[0] not in clients]
    assert server_side  # the app did log (start, warnings, ...)
    assert all(KEY not in r.getMessage() for r in server_side)


def test_the_redaction_filter_on_uvicorns_record_shapes():
    import logging

    from backend.main import RedactSecretQuery

    access = logging.LogRecord(
        "uvicorn.access",
        logging.INFO,
        __file__,
        1,
        '%s - "%s %s HTTP/%s" %d',
        ("127.0.0.1:5", "GET", f"/a?x=1&Token={KEY}&api_key={KEY}&k=2", "1.1", 200),
        None,
    )
    ws = logging.LogRecord(
        "uvicorn.error",
        logging.INFO,
        __file__,
        1,
        f'127.0.0.1:5 - "WebSocket /ws/live?ticket={KEY}" 403',
        None,
        None,
    )
    f = RedactSecretQuery()
    assert f.filter(access) and f.filter(ws)
    assert access.getMessage() == (
        '127.0.0.1:5 - "GET /a?x=1&Token=***&api_key=***&k=2 HTTP/1.1" 200'
    )
    assert ws.getMessage() == '127.0.0.1:5 - "WebSocket /ws/live?ticket=***" 403'
