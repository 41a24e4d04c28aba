"""Server memory through a day's use: ``tofpose serve`` with the simulated devices (as
``make run`` starts it, on a free port with a temporary data directory and database),
driven through its REST API and WebSocket as a new user would, its memory read after
each step.

Steps, in order (one "round" is steps 2-8; ``--rounds`` repeats them on the same server,
so growth from round to round is what an hour of use adds):

1. idle: health ok, kernels ready, an ok pose;
2. campaign: an accuracy campaign with ``record_raw`` (3 set-points) run to done;
3. report PDF and 4. report HTML of it;
5. MCAP export of its recording;
6. refused study: a spec over the server's size limits (422);
7. study: a small accepted study (2 cells) run to complete, and its HTML report;
8. 50 clients: 50 WebSocket clients on ``/ws/live`` (images on) for ``--ws-seconds``,
   then closed.

After each step: the server's RSS (psutil, the figure a user sees in ``top``) and its
private memory (``RssAnon``: heap, arrays, compiled kernels, without the shared
libraries' resident pages, which vary with the page cache; docs/server.md, "Memory").
Each repeat starts a fresh server; the table gives the median over repeats and the
largest value seen.

Run: ``python bench/memory.py [--repeats 3] [--rounds 2] [--ws-seconds 20]``
(``--imports``: also the memory each heavy module adds when imported, in a fresh
interpreter each).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import psutil
import websockets

ROOT = Path(__file__).resolve().parents[1]
WS_CLIENTS = 50
CAMPAIGN = {
    "name": "memory-bench",
    "catalog": "paper-target",
    "frames_per_point": 10,
    "settle_s": 0.2,
    "record_raw": True,
    "setpoints": [
        {"yaw_deg": 0, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 11000},
        {"yaw_deg": 5, "pitch_deg": 0, "roll_deg": 0, "rail_mm": 11000},
        {"yaw_deg": 0, "pitch_deg": 5, "roll_deg": 0, "rail_mm": 11000},
    ],
}
STUDY = {
    "name": "memory-bench",
    "frames_per_cell": 4,
    "chunk_frames": 4,
    "grid": {"range_m": [2.0, 4.0]},
}
#: over TOFPOSE_STUDY_MAX_CELLS (set below): refused from the axis lengths
STUDY_TOO_BIG = {
    "name": "too-big",
    "frames_per_cell": 1,
    "grid": {"range_m": [2.0, 3.0, 4.0, 5.0], "attitude_deg": [5.0, 10.0, 15.0, 20.0]},
}
IMPORTS = [
    "fastapi",
    "numba",
    "scipy.optimize",
    "cv2",
    "matplotlib.pyplot",
    "viser",
    "dask.distributed",
    "tofpose.pipeline",
    "tofpose.study.run",
    "backend.services.reports.reports",
    "backend.app",
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def memory_mb(pid: int) -> tuple[float, float]:
    """(RSS, private RssAnon) of ``pid`` in MiB."""
    rss = psutil.Process(pid).memory_info().rss / 2**20
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("RssAnon:"):
            return rss, int(line.split()[1]) / 1024.0
    raise RuntimeError("no RssAnon")


class Server:
    """``python -m tofpose.cli serve`` from this checkout, simulated devices, a free port,
    a temporary data directory (its SQLite database in it)."""

    def __init__(self, data_dir: Path) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = open(data_dir.parent / "serve.log", "w")  # noqa: SIM115
        env = {
            **os.environ,
            "PYTHONPATH": str(ROOT),
            "TOFPOSE_SIM_TIME_SCALE": "10",
            "TOFPOSE_LIVE_MAX_CLIENTS_PER_ADDRESS": str(WS_CLIENTS + 4),
            "TOFPOSE_LIVE_MAX_CLIENTS": str(WS_CLIENTS + 4),
            "TOFPOSE_STUDY_MAX_CELLS": "8",
            "TOFPOSE_STUDY_WORKERS": "1",
        }
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(self.port)]
            + ["--data-dir", str(data_dir), "--viser-port", str(free_port())],
            stdout=self.log,
            stderr=subprocess.STDOUT,
            env=env,
            cwd=ROOT,
        )
        self.data_dir = data_dir
        self.http = httpx.Client(base_url=self.url, timeout=300)
        try:
            self._wait_ready()
        except BaseException:
            self.stop()
            raise
        token = (data_dir / "api_token").read_text().strip()
        self.auth = {"Authorization": f"Bearer {token}"}

    def _wait_ready(self, timeout_s: float = 1200.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited: {self.proc.returncode}")
            try:
                h = self.http.get("/api/health", timeout=2).json()
                if (
                    h["camera"]["state"] == "ok"
                    and h["pipeline"]["state"] == "ready"
                    and self.http.get("/api/pose/latest", timeout=2).json()["ok"]
                ):
                    return
            except (httpx.HTTPError, KeyError, ValueError):
                pass
            time.sleep(0.5)
        raise RuntimeError("server did not come up")

    def memory(self) -> tuple[float, float]:
        return memory_mb(self.proc.pid)

    def stop(self) -> None:
        self.http.close()
        self.proc.terminate()
        try:
            self.proc.wait(60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.log.close()

    # -- the steps ------------------------------------------------------------------
    def campaign(self, name: str) -> int:
        body = {**CAMPAIGN, "name": name}
        r = self.http.post("/api/campaigns", json=body, headers=self.auth)
        r.raise_for_status()
        cid = r.json()["id"]
        self.http.post(f"/api/campaigns/{cid}/start", headers=self.auth).raise_for_status()
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:
            status = self.http.get(f"/api/campaigns/{cid}").json()["status"]
            if status == "done":
                return cid
            if status in ("failed", "aborted", "interrupted"):
                raise RuntimeError(f"campaign {cid}: {status}")
            time.sleep(1.0)
        raise RuntimeError(f"campaign {cid} did not finish")

    def get(self, path: str, expect: bytes = b"") -> None:
        r = self.http.get(path, headers=self.auth)
        r.raise_for_status()
        if not r.content.startswith(expect):
            raise RuntimeError(f"{path}: unexpected content {r.content[:20]!r}")

    def refused_study(self) -> None:
        r = self.http.post("/api/studies", json=STUDY_TOO_BIG, headers=self.auth)
        if r.status_code != 422:
            raise RuntimeError(f"the oversized study was not refused: {r.status_code}")

    def study(self, name: str) -> None:
        r = self.http.post("/api/studies", json={**STUDY, "name": name}, headers=self.auth)
        r.raise_for_status()
        sid = r.json()["id"]
        deadline = time.monotonic() + 900
        while time.monotonic() < deadline:
            s = self.http.get(f"/api/studies/{sid}").json()
            if s["status"] == "complete":
                self.get(f"/api/studies/{sid}/report.html", b"<!")
                return
            if s["status"] in ("failed", "incomplete"):
                raise RuntimeError(f"study {sid}: {s['status']} {s.get('error')}")
            time.sleep(1.0)
        raise RuntimeError(f"study {sid} did not finish")

    def ws_clients(self, seconds: float) -> int:
        """``WS_CLIENTS`` live clients with images on for ``seconds``; messages received."""

        async def one(counts: list[int]) -> None:
            url = f"ws://127.0.0.1:{self.port}/ws/live"
            async with websockets.connect(url, max_size=2**24) as ws:
                await ws.send('{"images": ["gray", "distance"], "image_every": 5}')
                stop_at = time.monotonic() + seconds
                while time.monotonic() < stop_at:
                    try:
                        await asyncio.wait_for(ws.recv(), timeout=1.0)
                        counts[0] += 1
                    except TimeoutError:
                        pass

        async def all_clients() -> int:
            counts = [0]
            await asyncio.gather(*(one(counts) for _ in range(WS_CLIENTS)))
            return counts[0]

        received = asyncio.run(all_clients())
        time.sleep(2.0)  # the server notices the closes
        return received


def one_repeat(rounds: int, ws_seconds: float) -> list[tuple[str, float, float]]:
    """[(step, RSS MiB, private MiB)] for one fresh server."""
    rows: list[tuple[str, float, float]] = []

    def note(step: str, server: Server) -> None:
        rows.append((step, *server.memory()))
        print(f"  {step}: RSS {rows[-1][1]:.0f}, private {rows[-1][2]:.0f} MiB", file=sys.stderr)

    with tempfile.TemporaryDirectory(prefix="tofpose-memory-") as tmp:
        server = Server(Path(tmp) / "data")
        try:
            time.sleep(2.0)
            note("idle", server)
            for r in range(1, rounds + 1):
                cid = server.campaign(f"memory-bench-{r}")
                note(f"round {r}: campaign (3 set-points, raw)", server)
                server.get(f"/api/campaigns/{cid}/report.pdf", b"%PDF")
                note(f"round {r}: report PDF", server)
                server.get(f"/api/campaigns/{cid}/report.html", b"<!")
                note(f"round {r}: report HTML", server)
                server.get(f"/api/campaigns/{cid}/recording.mcap", b"\x89MCAP")
                note(f"round {r}: MCAP export", server)
                server.refused_study()
                note(f"round {r}: refused study spec", server)
                server.study(f"memory-bench-{r}")
                note(f"round {r}: study (2 cells) + report", server)
                server.ws_clients(ws_seconds)
                note(f"round {r}: {WS_CLIENTS} WebSocket clients", server)
        finally:
            server.stop()
    return rows


def import_costs() -> list[tuple[str, float]]:
    """RSS (MiB) each module adds when imported after fastapi and numpy, in a fresh
    interpreter each (so shared dependencies are counted in each)."""
    out = []
    code = (
        "import importlib, sys, psutil, numpy, fastapi; p = psutil.Process();"
        "a = p.memory_info().rss; importlib.import_module(sys.argv[1]);"
        "print((p.memory_info().rss - a) / 2**20)"
    )
    for name in IMPORTS:
        r = subprocess.run(
            [sys.executable, "-c", code, name],
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            cwd=ROOT,
            check=True,
        )
        out.append((name, float(r.stdout.strip())))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--ws-seconds", type=float, default=20.0)
    ap.add_argument("--imports", action="store_true")
    args = ap.parse_args()
    runs = []
    for i in range(args.repeats):
        t0 = time.monotonic()
        runs.append(one_repeat(args.rounds, args.ws_seconds))
        print(f"repeat {i + 1}/{args.repeats}: {time.monotonic() - t0:.0f} s", file=sys.stderr)
    print(
        f"Server memory after each step, MiB, median of {args.repeats} fresh servers "
        f"(max in brackets); {WS_CLIENTS} clients for {args.ws_seconds:.0f} s:\n"
    )
    print("| step | RSS | private (RssAnon) |")
    print("|---|---:|---:|")
    for k, (step, _, _) in enumerate(runs[0]):
        rss = [run[k][1] for run in runs]
        anon = [run[k][2] for run in runs]
        print(
            f"| {step} | {statistics.median(rss):.0f} ({max(rss):.0f}) "
            f"| {statistics.median(anon):.0f} ({max(anon):.0f}) |"
        )
    if args.imports:
        print("\nRSS each module adds on import (after numpy and fastapi), MiB:\n")
        print("| module | MiB |")
        print("|---|---:|")
        for name, mb in import_costs():
            print(f"| `{name}` | {mb:.0f} |")


if __name__ == "__main__":
    main()
