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
    assert main(["serve", "--motion", "scpi:127.0.0.1:9", "--data-dir", str(tmp_path),
                 "--no-viser"]) == 2  # fmt: skip
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
