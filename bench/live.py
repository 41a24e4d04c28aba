"""Live server under WebSocket load: delivered rate per client and latency.

Starts ``tofpose serve`` (simulated devices) in a subprocess, connects N WebSocket
clients on loopback from this process, and measures for each client the delivered pose
messages per second and the latency from the moment the frame reached the server
(``captured_unix_s``, same machine clock) to its receipt by the client. Each setting is
repeated; the table gives medians over repeats of the per-run median / p95.

With ``--dashboards 1 5`` it also opens that many dashboards (the real page, in Debian's
chromium driven by Playwright) and measures the frames per second each page actually
drew (its ``window.__tofposeFramesDrawn`` counter: raw frames colour-mapped and put on a
canvas) and the server process's CPU (user + system time from /proc over wall time, in %
of one core). The 3-D scene is off in those runs unless ``--with-scene``: this machine has
no GPU, and software WebGL would measure SwiftShader, not the dashboard.

Run: ``python bench/live.py [--clients 1 10 50] [--rates 10 30] [--seconds 5] [--repeats 3]
[--dashboards 1 5] [--with-scene]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
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

from bench._common import all_cores, free_port, table  # noqa: E402


class Server:
    def __init__(self, rate_hz: float, scene: bool = False, env: dict | None = None) -> None:
        self.port = free_port()
        self.tmp = tempfile.TemporaryDirectory()
        env = {
            **os.environ,
            "TOFPOSE_FRAME_RATE_HZ": str(rate_hz),
            "TOFPOSE_DATA_DIR": self.tmp.name,
            **(env or {}),
        }
        scene_args = ["--viser-port", "0"] if scene else ["--no-viser"]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(self.port), *scene_args],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
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

    def cpu_s(self) -> float:
        """User + system CPU seconds the server process has used so far."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(30)
        self.tmp.cleanup()


async def pose_messages(ws, t_end: float):
    """(receipt wall-clock time, the message's data) of each pose message ``ws`` (a live
    WebSocket) receives until the monotonic clock reaches ``t_end``."""
    while (left := t_end - time.monotonic()) > 0:
        try:
            raw = await asyncio.wait_for(ws.recv(), left)
        except TimeoutError:
            return
        now = time.time()
        m = json.loads(raw)
        if m["type"] == "pose":
            yield now, m["data"]


async def _client(url: str, seconds: float, start: asyncio.Event):
    lat_ms, n, first, last = [], 0, None, None
    async with websockets.connect(url, max_queue=64, close_timeout=1) as ws:
        await ws.recv()  # hello
        while not start.is_set():  # keep reading during warm-up so nothing queues up
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(ws.recv(), 0.05)
        async for now, data in pose_messages(ws, time.monotonic() + seconds):
            lat_ms.append(1e3 * (now - data["captured_unix_s"]))
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


CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-gl=swiftshader",
    "--enable-unsafe-swiftshader",
    # five dashboards = five visible pages: without these, headless chromium treats all
    # but one window as occluded and stops their animation frames (as a hidden tab does)
    "--disable-backgrounding-occluded-windows",
    "--disable-renderer-backgrounding",
    "--disable-background-timer-throttling",
]
DRAWN = "() => window.__tofposeFramesDrawn || 0"


def dashboards(rate: float, n_pages: int, seconds: float, scene: bool) -> tuple[list, float]:
    """(frames/s drawn per page, server CPU % of one core) with ``n_pages`` dashboards."""
    from playwright.sync_api import sync_playwright

    server = Server(rate, scene=scene)
    base = f"http://127.0.0.1:{server.port}"
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            pages = []
            for _ in range(n_pages):
                page = browser.new_context(viewport={"width": 1366, "height": 768}).new_page()
                page.goto(base + "/")
                pages.append(page)
            for page in pages:
                page.wait_for_function(f"({DRAWN})() > 3", timeout=30_000)
            time.sleep(2.0)  # warm-up
            drawn0 = [pg.evaluate(DRAWN) for pg in pages]
            cpu0, t0 = server.cpu_s(), time.monotonic()
            time.sleep(seconds)
            drawn1 = [pg.evaluate(DRAWN) for pg in pages]
            cpu1, t1 = server.cpu_s(), time.monotonic()
            browser.close()
    finally:
        server.stop()
    fps = [(b - a) / (t1 - t0) for a, b in zip(drawn0, drawn1, strict=True)]
    return fps, 100.0 * (cpu1 - cpu0) / (t1 - t0)


def dashboard_table(rates, counts, seconds, repeats, scene: bool) -> str:
    rows = []
    bar = tqdm(
        total=len(rates) * len(counts) * repeats, desc="dashboards", unit="run", file=sys.stderr
    )
    for rate in rates:
        for n in counts:
            runs = []
            for _ in range(repeats):
                fps, cpu = dashboards(rate, n, seconds, scene)
                runs.append((np.median(fps), np.min(fps), cpu))
                bar.update()
            a = np.median(np.array(runs), axis=0)
            rows.append(
                [
                    f"{rate:g}",
                    str(n),
                    "on" if scene else "off",
                    f"{a[0]:.1f}",
                    f"{a[1]:.1f}",
                    f"{a[2]:.0f}",
                ]
            )
    bar.close()
    return table(
        [
            "camera Hz",
            "dashboards",
            "3-D scene",
            "frames drawn/s per page (median)",
            "slowest page",
            "server CPU % of one core",
        ],
        rows,
    )


def main() -> None:
    all_cores()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--clients", type=int, nargs="+", default=[1, 10, 50])
    ap.add_argument("--rates", type=float, nargs="+", default=[10.0, 30.0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--dashboards",
        type=int,
        nargs="*",
        default=[],
        help="also measure this many open dashboards in chromium, e.g. 1 5",
    )
    ap.add_argument("--with-scene", action="store_true", help="dashboards with the 3-D scene")
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
                    per_run.append(
                        (np.median(rates), np.min(rates), np.median(lat), np.percentile(lat, 95))
                    )
                    bar.update()
                a = np.median(np.array(per_run), axis=0)
                rows.append(
                    [
                        f"{rate:g}",
                        str(n),
                        f"{a[0]:.1f}",
                        f"{a[1]:.1f}",
                        f"{a[2]:.1f}",
                        f"{a[3]:.1f}",
                    ]
                )
        finally:
            server.stop()
    bar.close()
    print(
        table(
            [
                "camera Hz",
                "clients",
                "msg/s per client (median)",
                "slowest client msg/s",
                "latency median ms",
                "latency p95 ms",
            ],
            rows,
        )
    )
    if args.dashboards:
        print()
        print(
            dashboard_table(
                args.rates, args.dashboards, args.seconds, args.repeats, args.with_scene
            )
        )


if __name__ == "__main__":
    main()
