"""``tofpose serve`` in a subprocess for a benchmark: start it on a free port (simulated
devices unless the environment says otherwise, no 3-D scene), wait for a live camera and
a ready pipeline, stop it as Ctrl-C would (``bench/latency.py``,
``bench/stop_latency.py``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request

from bench._common import free_port

#: a first start compiles the pipeline's kernels
READY_TIMEOUT_S = 900.0


def health(port: int, timeout_s: float) -> dict:
    """``/api/health`` of the server on ``port`` (raises ``OSError`` when it does not
    answer within ``timeout_s``)."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/health", timeout=timeout_s) as r:
        return json.load(r)


def start_serve(
    env: dict[str, str], what: str, poll_timeout_s: float
) -> tuple[subprocess.Popen, int]:
    """``python -m tofpose.cli serve --no-viser`` on a free port with ``env`` over this
    process's environment, waited for until its camera is ``ok`` and its pipeline
    ``ready`` (each health request waits ``poll_timeout_s``); (process, port). Raises
    ``RuntimeError`` naming ``what`` when it exits or is not ready in
    ``READY_TIMEOUT_S`` (then it is killed)."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(port), "--no-viser"],
        env={**os.environ, **env},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"server for {what} exited ({proc.returncode})")
        try:
            h = health(port, poll_timeout_s)
            if h["camera"]["state"] == "ok" and h["pipeline"]["state"] == "ready":
                return proc, port
        except OSError:
            pass
        time.sleep(0.2)
    stop_serve(proc)
    raise RuntimeError(f"server for {what} did not start")


def stop_serve(proc: subprocess.Popen) -> None:
    """SIGINT (the server's orderly shutdown), killed after 30 s."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
