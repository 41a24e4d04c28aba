"""``tofpose serve``: the README's main command, end to end in a subprocess."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import urllib.request

from tofpose.cli import main


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_starts_prints_urls_and_token_and_stops_cleanly(tmp_path):
    port = _free_port()
    data = tmp_path / "data"
    proc = subprocess.Popen(
        [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(port), "--data-dir",
         str(data)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        health = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and health is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/health", timeout=2) as r:
                    h = json.load(r)
                    health = h if h["camera"]["state"] == "ok" else None
            except OSError:
                pass
            time.sleep(0.2)
        assert health is not None and health["status"] == "ok", "server did not come up"
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/pose/latest", timeout=5) as r:
            assert json.load(r)["ok"]
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    token = (data / "api_token").read_text().strip()
    assert f"http://127.0.0.1:{port}/docs" in out
    assert f"ws://127.0.0.1:{port}/ws/live" in out
    assert f"sqlite:///{(data / 'tofpose.db').resolve()}" in out
    assert token in out and "generated now" in out


def test_serve_refuses_bad_options_with_a_message(tmp_path, capsys):
    assert main(["serve", "--camera", "usb3", "--data-dir", str(tmp_path)]) == 2
    assert "camera must be 'sim' or 'replay:PATH.h5'" in capsys.readouterr().err
    missing = tmp_path / "missing.h5"
    assert main(["serve", "--camera", f"replay:{missing}", "--data-dir", str(tmp_path)]) == 2
    assert "cannot replay" in capsys.readouterr().err
