"""Open reads at full speed cannot grow the server's memory or slow the live loop.

A real ``tofpose serve`` subprocess (so the memory is the server's alone); 6 clients
fetch every PNG variant of the latest frame as fast as they can for 12 s. docs/server.md
states the ceiling this checks, on the server's private (anonymous) memory: the shared
libraries' resident pages vary with the page cache by tens of MB from run to run.
"""

from __future__ import annotations

import itertools
import threading
import time

import httpx

from tests.backend.serve_process import ServeProcess

PRIVATE_CEILING_MB = 380.0  # docs/server.md, "Memory": the server's own (anonymous) pages
PRIVATE_GROWTH_MB = 60.0  # above the idle server, under the read load
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
