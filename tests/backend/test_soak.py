"""Open reads at full speed cannot grow the server's memory or slow the live loop, and
a day's use (campaigns, reports, MCAP exports, studies, 50 live clients) leaves it flat.

A real ``tofpose serve`` subprocess (so the memory is the server's alone). First: 6
clients fetch every PNG variant of the latest frame as fast as they can for 12 s. Then:
rounds of ``bench/memory.py``'s workload; the first round loads what each route imports
on first use (matplotlib, pyarrow, Dask), later rounds must not add more than a bound,
and every live client's state must go when it disconnects. docs/server.md ("Memory")
states the ceiling this checks, on the server's private (anonymous) memory: the shared
libraries' resident pages vary with the page cache by tens of MB from run to run.
"""

from __future__ import annotations

import asyncio
import itertools
import threading
import time

import httpx
import pytest
import websockets

from bench.memory import CAMPAIGN, STUDY, STUDY_TOO_BIG, WS_CLIENTS
from tests.backend.serve_process import ServeProcess

PRIVATE_CEILING_MB = 380.0  # docs/server.md, "Memory": the server's own (anonymous) pages
PRIVATE_GROWTH_MB = 60.0  # above the idle server, under the read load
DAY_PRIVATE_CEILING_MB = 550.0  # docs/server.md, "Memory": after a day's workload
DAY_ROUNDS = 3
# the first two rounds load what the routes import on first use and fill the allocator's
# arenas (docs/server.md, "Memory"); the third must add less than this
WARM_UP_ROUNDS = 2
ROUND_GROWTH_MB = 20.0
VARIANTS = [
    f"/api/frames/latest/{kind}.png?overlay={o}&scale={s}"
    for kind in ("gray", "distance")
    for o in (0, 1)
    for s in (1, 2, 3, 4)
]


def _rate_hz(server: ServeProcess, seconds: float) -> float:
    f0 = server.get_json("/api/devices")["camera"]["frames_processed"]
    t0 = time.monotonic()
    time.sleep(seconds)
    f1 = server.get_json("/api/devices", 10.0)["camera"]["frames_processed"]
    return (f1 - f0) / (time.monotonic() - t0)


def test_png_reads_at_full_speed_keep_memory_bounded_and_the_live_rate(tmp_path):
    with ServeProcess(tmp_path / "data") as server:
        idle_rate = _rate_hz(server, 4.0)
        idle_mb = server.private_mb()
        stop_at = time.monotonic() + 12.0
        served, errors = [0], []

        def client(offset: int) -> None:
            with httpx.Client(base_url=server.base_url, timeout=20) as c:
                for path in itertools.islice(itertools.cycle(VARIANTS), offset, None):
                    if time.monotonic() > stop_at:
                        return
                    r = c.get(path)
                    if r.status_code != 200 or r.content[:4] != b"\x89PNG":
                        errors.append(f"{path}: {r.status_code}")
                        return
                    served[0] += 1

        threads = [threading.Thread(target=client, args=(i,)) for i in range(6)]
        for t in threads:
            t.start()
        private = []
        time.sleep(1.0)
        loaded_rate = _rate_hz(server, 8.0)
        while any(t.is_alive() for t in threads):
            private.append(server.private_mb())
            time.sleep(0.5)
        for t in threads:
            t.join()
        private.append(server.private_mb())
    assert not errors, errors[:3]
    assert served[0] > 100
    assert max(private) < PRIVATE_CEILING_MB, f"private memory peaked at {max(private):.0f} MB"
    assert max(private) - idle_mb < PRIVATE_GROWTH_MB, (idle_mb, max(private))
    assert loaded_rate > 0.6 * idle_rate, (idle_rate, loaded_rate)


def _day_round(server: ServeProcess, c: httpx.Client, r: int) -> None:
    """One round of the day's workload (bench/memory.py): a campaign with its raw
    recording run to done, its PDF and HTML report, its MCAP export, a refused and an
    accepted study (and its report), then ``WS_CLIENTS`` live clients for 10 s."""
    cid = c.post("/api/campaigns", json={**CAMPAIGN, "name": f"day-{r}"}).json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 200
    deadline = time.monotonic() + 600
    while (status := c.get(f"/api/campaigns/{cid}").json()["status"]) != "done":
        assert status not in ("failed", "paused") and time.monotonic() < deadline, status
        time.sleep(1.0)
    assert c.get(f"/api/campaigns/{cid}/report.pdf").content[:4] == b"%PDF"
    assert "<html" in c.get(f"/api/campaigns/{cid}/report.html").text[:200].lower()
    assert c.get(f"/api/campaigns/{cid}/recording.mcap").content[:5] == b"\x89MCAP"
    assert c.post("/api/studies", json=STUDY_TOO_BIG).status_code == 422
    sid = c.post("/api/studies", json={**STUDY, "name": f"day-{r}"}).json()["id"]
    while (status := c.get(f"/api/studies/{sid}").json()["status"]) != "complete":
        assert status not in ("failed", "incomplete") and time.monotonic() < deadline, status
        time.sleep(1.0)
    assert c.get(f"/api/studies/{sid}/report.html").status_code == 200

    async def client(connected: asyncio.Event, counts: list[int]) -> None:
        async with websockets.connect(f"ws://127.0.0.1:{server.port}/ws/live") as ws:
            await ws.send('{"images": ["gray", "distance"], "image_every": 5}')
            counts[0] += 1
            await connected.wait()
            stop_at = time.monotonic() + 10.0
            while time.monotonic() < stop_at:
                try:
                    await asyncio.wait_for(ws.recv(), timeout=1.0)
                    counts[1] += 1
                except TimeoutError:
                    pass

    async def clients() -> tuple[int, int]:
        connected, counts = asyncio.Event(), [0, 0, 0]

        async def all_connected() -> None:
            while counts[0] < WS_CLIENTS:
                await asyncio.sleep(0.1)
            stats = await asyncio.to_thread(c.get, "/api/live/stats")
            counts[2] = len(stats.json()["clients"])
            connected.set()

        await asyncio.gather(
            all_connected(), *(client(connected, counts) for _ in range(WS_CLIENTS))
        )
        return counts[1], counts[2]

    received, listed = asyncio.run(clients())
    assert listed == WS_CLIENTS and received > WS_CLIENTS * 10, (listed, received)
    deadline = time.monotonic() + 10
    while c.get("/api/live/stats").json()["clients"]:  # each client's state goes with it
        assert time.monotonic() < deadline, "live clients still listed after they closed"
        time.sleep(0.2)


def test_a_days_workload_leaves_the_server_memory_flat(tmp_path, request):
    markexpr = request.config.option.markexpr or ""
    if "soak" not in markexpr or "not soak" in markexpr:
        pytest.skip("minutes long: runs only when the soak tier is asked for (pytest -m soak)")
    env = {
        "TOFPOSE_SIM_TIME_SCALE": "10",
        "TOFPOSE_LIVE_MAX_CLIENTS_PER_ADDRESS": str(WS_CLIENTS + 4),
        "TOFPOSE_LIVE_MAX_CLIENTS": str(WS_CLIENTS + 4),
        "TOFPOSE_STUDY_MAX_CELLS": "8",
        "TOFPOSE_STUDY_WORKERS": "1",
    }
    with ServeProcess(tmp_path / "data", env=env) as server:
        idle_mb = server.private_mb()
        after_round = []
        auth = {"Authorization": f"Bearer {server.token}"}
        with httpx.Client(base_url=server.base_url, timeout=300, headers=auth) as c:
            for r in range(1, DAY_ROUNDS + 1):
                _day_round(server, c, r)
                after_round.append(server.private_mb())
    print(f"private MiB: idle {idle_mb:.0f}, after each round {after_round}")
    assert max(after_round) < DAY_PRIVATE_CEILING_MB, (idle_mb, after_round)
    growth = after_round[-1] - after_round[WARM_UP_ROUNDS - 1]
    assert growth < ROUND_GROWTH_MB, (idle_mb, after_round)
