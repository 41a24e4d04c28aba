"""Shutdown finishes within a few seconds whatever the WebSocket clients do."""

from __future__ import annotations

import base64
import os
import signal
import socket
import time

from tests.backend.serve_process import ServeProcess

SHUTDOWN_BOUND_S = 10.0  # docs/server.md, "Shutdown": graceful timeout 3 s + teardown


def _raw_ws_client_that_never_reads(port: int) -> socket.socket:
    """Complete the WebSocket handshake, ask for full-size images, then never read."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)  # before connect: tiny window
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            "GET /ws/live HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    payload = b'{"images": ["gray", "distance"], "image_every": 1, "image_step": 1}'
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    s.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + masked)
    return s


def test_sigterm_finishes_while_websocket_clients_do_not_read(tmp_path):
    with ServeProcess(tmp_path / "data") as server:
        clients = [_raw_ws_client_that_never_reads(server.port) for _ in range(5)]
        time.sleep(5.0)  # let the server's send buffers towards them fill up
        assert server.get_json("/api/health")["status"] == "ok"
        took = server.stop(signal.SIGTERM, timeout_s=60.0)
        for c in clients:
            c.close()
    # uvicorn re-raises the signal after a graceful shutdown: exit status -SIGTERM
    assert server.proc.returncode in (0, -signal.SIGTERM), server.output
    assert "Application shutdown complete" in server.output, server.output
    print(f"shutdown took {took:.1f} s")
    assert took < SHUTDOWN_BOUND_S, f"shutdown took {took:.1f} s"
