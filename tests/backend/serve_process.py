"""``tofpose serve`` in a real subprocess, for tests that need signals, RSS or restarts."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServeProcess:
    """Start ``python -m tofpose.cli serve`` on a free loopback port with ``data_dir``;
    ``__enter__`` waits until /api/health reports the camera ok and the pipeline's kernels
    ready, and the latest pose is ok."""

    def __init__(self, data_dir: Path, *args: str, env: dict[str, str] | None = None) -> None:
        self.port = free_port()
        self.data_dir = data_dir
        self.base_url = f"http://127.0.0.1:{self.port}"
        cmd = [
            sys.executable,
            "-m",
            "tofpose.cli",
            "serve",
            "--port",
            str(self.port),
            "--data-dir",
            str(data_dir),
            "--viser-port",
            "0",
            *args,
        ]
        # Output to a file, not a pipe: a server logging every request would block on a
        # full pipe that nobody reads.
        data_dir.parent.mkdir(parents=True, exist_ok=True)
        self._log_path = data_dir.parent / f"serve-{self.port}.log"
        self._log = open(self._log_path, "w")  # noqa: SIM115 (closed in stop)
        self.proc = subprocess.Popen(
            cmd,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, **(env or {})},
        )

    @property
    def output(self) -> str:
        """Everything the server printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self._log_path.read_text()

    def get_json(self, path: str, timeout_s: float = 5.0):
        with urllib.request.urlopen(self.base_url + path, timeout=timeout_s) as r:
            return json.load(r)

    def wait_healthy(self, timeout_s: float = 60.0) -> dict:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise AssertionError(f"server exited early:\n{self.output}")
            try:
                h = self.get_json("/api/health", 2.0)
                # camera up, the kernels compiled in the background (docs/server.md,
                # "First start") and a pose measured with them
                if (
                    h["camera"]["state"] == "ok"
                    and h["pipeline"]["state"] == "ready"
                    and self.get_json("/api/pose/latest", 2.0)["ok"]
                ):
                    return h
            except OSError:
                pass
            time.sleep(0.2)
        raise AssertionError("server did not come up")

    @property
    def token(self) -> str:
        return (self.data_dir / "api_token").read_text().strip()

    def private_mb(self) -> float:
        """The server's own resident memory (Linux /proc ``RssAnon``), MiB: anonymous
        pages (heap, arrays, compiled kernels), without the resident pages of the shared
        libraries and files it maps, which depend on the page cache (docs/server.md,
        "Memory")."""
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("RssAnon:"):
                return int(line.split()[1]) / 1024.0
        raise RuntimeError("no RssAnon")

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 30.0) -> float:
        """Send ``sig`` and wait for exit; returns the seconds it took. Kills on timeout
        (and raises ``subprocess.TimeoutExpired``)."""
        t0 = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise
        finally:
            self._log.close() if self.proc.poll() is not None else None
        return time.monotonic() - t0

    def __enter__(self) -> ServeProcess:
        try:
            self.wait_healthy()
        except BaseException:
            self.stop(signal.SIGKILL)
            raise
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.stop()
