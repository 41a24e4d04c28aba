"""Live server under WebSocket load: delivered rate per client and latency.

Starts ``tofpose serve`` (simulated devices) in a subprocess, connects N WebSocket
clients on loopback from this process, and measures for each client the delivered pose
messages per second and the latency from the moment the frame reached the server
(``captured_unix_s``, same machine clock) to its receipt by the client. Each setting is
repeated; the table gives medians over repeats of the per-run median / p95.

Run: ``python bench/live.py [--clients 1 10 50] [--rates 10 30] [--seconds 5] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np
import websockets
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import contextlib

from bench._common import table  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    def __init__(self, rate_hz: float) -> None:
        self.port = _free_port()
        self.tmp = tempfile.TemporaryDirectory()
        env = {**os.environ, "TOFPOSE_FRAME_RATE_HZ": str(rate_hz),
               "TOFPOSE_DATA_DIR": self.tmp.name}  # fmt: skip
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(self.port)],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                url = f"http://127.0.0.1:{self.port}/api/health"
                with urllib.request.urlopen(url, timeout=1) as r:
                    if json.load(r)["camera"]["state"] == "ok":
                        return
            except OSError:
                time.sleep(0.2)
        raise RuntimeError("server did not start")

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(30)
        self.tmp.cleanup()


async def _client(url: str, seconds: float, start: asyncio.Event):
    lat_ms, n, first, last = [], 0, None, None
    async with websockets.connect(url, max_queue=64, close_timeout=1) as ws:
        await ws.recv()  # hello
        while not start.is_set():  # keep reading during warm-up so nothing queues up
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(ws.recv(), 0.05)
        t_end = time.monotonic() + seconds
        while (left := t_end - time.monotonic()) > 0:
            try:
                raw = await asyncio.wait_for(ws.recv(), left)
            except TimeoutError:
                break
            now = time.time()
            m = json.loads(raw)
            if m["type"] != "pose":
                continue
            lat_ms.append(1e3 * (now - m["data"]["captured_unix_s"]))
            n += 1
            first = first or time.monotonic()
            last = time.monotonic()
    rate = (n - 1) / (last - first) if n > 1 and last > first else 0.0
    return rate, lat_ms


async def _run(url: str, n_clients: int, seconds: float):
    start = asyncio.Event()
    tasks = [asyncio.create_task(_client(url, seconds, start)) for _ in range(n_clients)]
    await asyncio.sleep(1.0)  # let every client connect
    start.set()
    return await asyncio.gather(*tasks)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--clients", type=int, nargs="+", default=[1, 10, 50])
    ap.add_argument("--rates", type=float, nargs="+", default=[10.0, 30.0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    rows = []
    jobs = [(r, n) for r in args.rates for n in args.clients]
    bar = tqdm(total=len(jobs) * args.repeats, desc="live bench", unit="run", file=sys.stderr)
    for rate in args.rates:
        server = Server(rate)
        url = f"ws://127.0.0.1:{server.port}/ws/live"
        try:
            for n in args.clients:
                per_run = []
                for _ in range(args.repeats):
                    res = asyncio.run(_run(url, n, args.seconds))
                    rates = [r for r, _ in res]
                    lat = np.concatenate([np.asarray(lt) for _, lt in res])
                    per_run.append((np.median(rates), np.min(rates), np.median(lat),
                                    np.percentile(lat, 95)))  # fmt: skip
                    bar.update()
                a = np.median(np.array(per_run), axis=0)
                rows.append([f"{rate:g}", str(n), f"{a[0]:.1f}", f"{a[1]:.1f}",
                             f"{a[2]:.1f}", f"{a[3]:.1f}"])  # fmt: skip
        finally:
            server.stop()
    bar.close()
    print(table(["camera Hz", "clients", "msg/s per client (median)", "slowest client msg/s",
                 "latency median ms", "latency p95 ms"], rows))  # fmt: skip


if __name__ == "__main__":
    main()
