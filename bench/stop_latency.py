"""STOP latency with mute /ws/live clients (issue 45, item 2), and with dashboards.

Starts ``tofpose serve`` (simulated devices, no 3-D scene) in a subprocess, opens N
WebSocket clients on /ws/live that complete the handshake (offering permessage-deflate,
as browsers do) and then never read a byte, and ``--readers`` clients that ask for
full-size raw frames at every frame, as the dashboard does, and read everything (in
threads of this process; "readers MB/s" is what they got in all, 307 kB a frame);
waits ``--settle`` seconds, and times
``POST /api/motion/stop`` with the admin key ``--stops`` times, a new connection each
time (as a dashboard's first click after idling). Each client count runs on a fresh
server. Prints the median, 95th percentile and maximum STOP time per client count, how
many clients the server accepted (the rest were refused by the per-address / total caps,
close code 1013) and the server's CPU while the mute clients were connected.

The caps are raised for the run (``--caps N``) so that every client is served: the
point is what mute clients cost the event loop, not the caps. ``--caps 0`` keeps the
defaults (16 per address), which is what a lab server runs with.

Run: ``python bench/stop_latency.py [--clients 0 100] [--readers 0] [--rate 20] [--stops 40]``
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import socket
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import all_cores, table  # noqa: E402
from bench._serve import start_serve, stop_serve  # noqa: E402


class Server:
    """``tofpose serve`` on a free port with a fresh data directory."""

    def __init__(self, rate_hz: float, caps: int) -> None:
        self.tmp = tempfile.TemporaryDirectory()
        env = {"TOFPOSE_FRAME_RATE_HZ": str(rate_hz), "TOFPOSE_DATA_DIR": self.tmp.name}
        if caps:
            env |= {
                "TOFPOSE_LIVE_MAX_CLIENTS_PER_ADDRESS": str(caps),
                "TOFPOSE_LIVE_MAX_CLIENTS": str(caps),
            }
        self.proc, self.port = start_serve(env, "the STOP bench", poll_timeout_s=1.0)
        self.key = (Path(self.tmp.name) / "api_token").read_text().strip()

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self.port}{path}"

    def rss_mb(self) -> float:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def request(
        self, method: str, path: str, body: dict | None = None, timeout_s: float = 120.0
    ) -> tuple[int, bytes]:
        """(status, body) of one request with the admin key."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(
            self.url(path),
            method=method,
            data=data,
            headers={"Authorization": f"Bearer {self.key}", "Content-Type": "application/json"},
        )
        try:
            with urllib.request.urlopen(req, timeout=timeout_s) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read()

    def cpu_s(self) -> float:
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        stop_serve(self.proc)
        self.tmp.cleanup()


RAW_OPTIONS = b'{"raw":true,"raw_credit":0,"image_every":1,"image_step":1}'


def masked_text_frame(payload: bytes) -> bytes:
    """A client-to-server WebSocket text frame (short payload, masked as clients must)."""
    mask = os.urandom(4)
    return (
        bytes([0x81, 0x80 | len(payload)])
        + mask
        + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    )


def reader(port: int, stop: threading.Event, measuring: threading.Event, got: list[int]) -> None:
    """A dashboard-like client: raw frames at every frame, everything read (and dropped);
    appends the bytes it read while ``measuring`` was set to ``got``."""
    s = handshake(port)
    if s is None:
        return
    s.sendall(masked_text_frame(RAW_OPTIONS))
    s.settimeout(0.5)
    n = 0
    while not stop.is_set():
        try:
            chunk = s.recv(1 << 20)
        except TimeoutError:
            continue
        if not chunk:
            break
        n += len(chunk) if measuring.is_set() else 0
    got.append(n)
    s.close()


def mute_client(port: int) -> socket.socket | None:
    """A WebSocket handshake on /ws/live, then nothing read: the socket, or None when the
    server refused it (a cap: it accepts, then closes with 1013)."""
    return handshake(port)


def handshake(port: int) -> socket.socket | None:
    """A WebSocket handshake on /ws/live (offering permessage-deflate): the socket, or
    None when the server refused it."""
    s = socket.create_connection(("127.0.0.1", port))
    nonce = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            "GET /ws/live HTTP/1.1\r\n"
            f"Host: 127.0.0.1:{port}\r\n"
            "Upgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {nonce}\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Extensions: permessage-deflate; client_max_window_bits\r\n\r\n"
        ).encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = s.recv(1)
        if not chunk:
            return None
        head += chunk
    if b" 101 " not in head.split(b"\r\n", 1)[0]:
        s.close()
        return None
    # the first frame tells a served client (hello) from a refused one (close, 1013)
    s.settimeout(5.0)
    first = s.recv(2)
    s.settimeout(None)
    if first[:1] in (b"\x88",):  # FIN + close opcode
        s.close()
        return None
    return s


def time_stops(server: Server, n: int, gap_s: float) -> list[float]:
    out = []
    for _ in range(n):
        req = urllib.request.Request(
            server.url("/api/motion/stop"),
            method="POST",
            headers={"Authorization": f"Bearer {server.key}"},
        )
        t0 = time.perf_counter()
        with urllib.request.urlopen(req, timeout=30) as r:
            r.read()
        out.append(time.perf_counter() - t0)
        time.sleep(gap_s)
    return out


def run(
    n_clients: int, n_readers: int, rate: float, stops: int, settle_s: float, caps: int
) -> list[str]:
    server = Server(rate, caps)
    stop, measuring, got = threading.Event(), threading.Event(), []
    readers = [
        threading.Thread(target=reader, args=(server.port, stop, measuring, got), daemon=True)
        for _ in range(n_readers)
    ]
    try:
        for t in readers:
            t.start()
        socks = [s for _ in range(n_clients) if (s := mute_client(server.port)) is not None]
        time.sleep(settle_s)
        cpu0, t0 = server.cpu_s(), time.monotonic()
        measuring.set()
        ms = 1e3 * np.array(time_stops(server, stops, 0.2))
        measuring.clear()
        elapsed = time.monotonic() - t0
        cpu = 100 * (server.cpu_s() - cpu0) / elapsed
        for s in socks:
            s.close()
    finally:
        stop.set()
        for t in readers:
            t.join(5.0)
        server.stop()
    mb_s = sum(got) / elapsed / 1e6
    return [
        str(n_clients),
        str(len(socks)),
        str(n_readers),
        f"{mb_s:.1f}",
        f"{np.median(ms):.1f}",
        f"{np.percentile(ms, 95):.1f}",
        f"{ms.max():.1f}",
        f"{cpu:.0f}",
    ]


CAMPAIGN = {
    "name": "export-load",
    "frames_per_point": 30,
    "settle_s": 0.2,
    "record_raw": True,
    "setpoints": [{"yaw_deg": 2.0 * i, "rail_mm": 12000} for i in range(4)],
}
HUGE_STUDY = {
    "name": "huge",
    "frames_per_cell": 1,
    "grid": {
        "range_m": [1.0 + 0.25 * i for i in range(64)],
        "attitude_deg": [0.5 * i for i in range(64)],
        "offset_fraction": [0.01 * i for i in range(64)],
        "physics": ["ideal", "grey plate", "lens blur", "gains", "systematic", "background", "all"],
    },
}
"""64 x 64 x 64 x 7 = 1,835,008 cells: far beyond TOFPOSE_STUDY_MAX_CELLS."""


def _finished_campaign(server: Server) -> int:
    status, body = server.request("POST", "/api/campaigns", CAMPAIGN)
    cid = json.loads(body)["id"]
    server.request("POST", f"/api/campaigns/{cid}/start")
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        if json.loads(server.request("GET", f"/api/campaigns/{cid}")[1])["status"] == "done":
            return cid
        time.sleep(0.5)
    raise RuntimeError("the export campaign did not finish")


def run_exports(n: int, rate: float, stops: int) -> list[str]:
    """STOP timed while ``n`` clients download a report or the MCAP of one campaign."""
    server = Server(rate, 0)
    try:
        cid = _finished_campaign(server)
        codes: list[int] = []
        paths = [f"/api/campaigns/{cid}/report.pdf", f"/api/campaigns/{cid}/recording.mcap"]

        def download(k: int) -> None:
            codes.append(server.request("GET", paths[k % 2], timeout_s=600)[0])

        threads = [threading.Thread(target=download, args=(k,)) for k in range(n)]
        for t in threads:
            t.start()
        time.sleep(0.3)  # the downloads are in the server before the first STOP
        ms = 1e3 * np.array(time_stops(server, stops, 0.1))
        busy_during = sum(t.is_alive() for t in threads)
        for t in threads:
            t.join()
    finally:
        server.stop()
    return [
        str(n),
        str(codes.count(200)),
        str(codes.count(503)),
        str(busy_during),
        f"{np.median(ms):.1f}",
        f"{np.percentile(ms, 95):.1f}",
        f"{ms.max():.1f}",
    ]


def run_study_refusals(repeats: int = 20) -> list[str]:
    """Median and max ms of refusing ``HUGE_STUDY``, and the server's RSS around it."""
    server = Server(10.0, 0)
    try:
        server.request("GET", "/api/studies")  # warm
        rss0 = server.rss_mb()
        ms = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            status, body = server.request("POST", "/api/studies", HUGE_STUDY)
            ms.append(1e3 * (time.perf_counter() - t0))
            if status != 422:
                raise RuntimeError(f"the huge study was not refused: {status} {body[:200]!r}")
        rss1 = server.rss_mb()
        detail = json.loads(body)["detail"][0]["msg"]
    finally:
        server.stop()
    return [
        f"{len(ms)}",
        f"{np.median(ms):.1f}",
        f"{max(ms):.1f}",
        f"{rss0:.0f}",
        f"{rss1:.0f}",
        detail[:90],
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, nargs="+", default=[0, 100])
    ap.add_argument(
        "--readers", type=int, default=0, help="dashboard-like clients reading full-size raw frames"
    )
    ap.add_argument("--rate", type=float, default=20.0, help="camera frame rate, Hz")
    ap.add_argument("--stops", type=int, default=40)
    ap.add_argument(
        "--settle",
        type=float,
        default=5.0,
        help="seconds between the last client and the first STOP",
    )
    ap.add_argument(
        "--exports",
        type=int,
        default=60,
        help="concurrent report/MCAP downloads while STOP is timed (0: skip)",
    )
    ap.add_argument(
        "--caps",
        type=int,
        default=1000,
        help="per-address and total /ws/live caps for the run (0: the defaults)",
    )
    args = ap.parse_args()
    all_cores()
    rows = [
        run(n, args.readers, args.rate, args.stops, args.settle, args.caps) for n in args.clients
    ]
    print(f"camera {args.rate:g} Hz, {args.stops} STOPs 0.2 s apart, {os.cpu_count()} cores")
    print(
        table(
            [
                "mute clients",
                "served",
                "raw readers",
                "readers MB/s",
                "STOP median ms",
                "p95 ms",
                "max ms",
                "server CPU %",
            ],
            rows,
        )
    )
    if args.exports:
        exp = run_exports(args.exports, args.rate, args.stops)
        print()
        print(
            f"STOP during {args.exports} concurrent downloads (PDF report and MCAP, half each) "
            "of one campaign (4 set-points x 30 frames, raw recording)"
        )
        print(
            table(
                [
                    "downloads",
                    "served (200)",
                    "refused (503)",
                    "still running at last STOP",
                    "STOP median ms",
                    "p95 ms",
                    "max ms",
                ],
                [exp],
            )
        )
    ref = run_study_refusals()
    print()
    print("POST /api/studies with a 1,835,008-cell spec (refused, 422)")
    print(
        table(
            ["requests", "median ms", "max ms", "server RSS before MB", "after MB", "the refusal"],
            [ref],
        )
    )


if __name__ == "__main__":
    main()
