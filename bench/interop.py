"""Interop (docs/interop.md): MCAP export / import speed and memory, the live Foxglove
server's cost to the camera loop, and a screenshot of Rerun's viewer on an export.

1. Files: a simulated recording (the realistic scene) cycled to N frames; ``tofpose
   export mcap`` with and without the pipeline's estimates and ``tofpose import mcap``,
   frames per second (median over repeats), and the export's peak memory (a fresh
   process's max RSS) for two lengths: streaming means it does not grow with N.
2. Live: ``tofpose serve`` at 30 Hz; the rate /ws/live delivers poses (the camera loop)
   with the Foxglove server off, on without a client, on with a client reading every
   channel, one reading far fewer messages than are published (the SDK drops the oldest
   of its backlog: it reads few images, and recent ones), and one that subscribes to
   every channel and never reads; what the Foxglove server published.
3. ``--screenshot PNG``: Rerun's web viewer (``rerun --serve-web REC.mcap``) in Debian's
   chromium with software WebGL.

Run: ``python bench/interop.py [--frames 1000 10000] [--repeats 3] [--seconds 5]
[--screenshot docs/img/interop/rerun.png]``
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import json
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._common import all_cores, free_port, table  # noqa: E402
from bench._rerun_web import rerun_web_screenshot  # noqa: E402
from bench.live import Server, _run  # noqa: E402
from tofpose.cli import main as tofpose_cli  # noqa: E402
from tofpose.io.recording import RecordingWriter, open_recording  # noqa: E402

PEAK_RSS = """
import resource, sys, time
from tofpose.io.interop.mcap_export import export_mcap
from tofpose.io.recording import open_recording
with open_recording(sys.argv[1]) as rec:
    t0 = time.perf_counter()
    export_mcap(rec, sys.argv[2], None, progress=False, overwrite=True)
    dt = time.perf_counter() - t0
print(dt, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def tofpose(args: list[str]) -> int:
    """``tofpose ARGS`` in this process, its summary line kept out of our tables."""
    with contextlib.redirect_stdout(io.StringIO()):
        return tofpose_cli(args)


def cycled(base: Path, out: Path, n: int) -> Path:
    """A recording of ``n`` frames cycling those of ``base`` (times 1/30 s apart)."""
    with open_recording(base) as rec:
        frames = [rec.frame(i)[:2] for i in range(rec.n_frames)]
        with RecordingWriter(out, rec.camera, rec.catalog) as w:
            for i in tqdm(
                range(n),
                desc=f"recording of {n} frames",
                unit="frame",
                file=sys.stderr,
                leave=False,
            ):
                gray, dist = frames[i % len(frames)]
                w.append(gray, dist, i / 30.0)
    return out


def _rate(args: list[str], n: int, repeats: int) -> float:
    """Median frames/s of ``tofpose ARGS`` over ``repeats`` runs of ``n`` frames."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        assert tofpose(args) == 0
        times.append(time.perf_counter() - t0)
    return n / statistics.median(times)


def file_table(lengths: list[int], repeats: int, tmp: Path) -> str:
    base = tmp / "base.h5"
    assert (
        tofpose(
            [
                "simulate",
                "--scenario",
                "realistic",
                "--frames",
                "24",
                "--out",
                str(base),
                "--seed",
                "0",
            ]
        )
        == 0
    )
    short = cycled(base, tmp / "short.h5", 120)
    mcap, back = tmp / "short.mcap", tmp / "back.h5"
    rows = []
    for label, extra in (
        ("export, frames only", ["--no-estimate"]),
        ("export with the estimates", []),
    ):
        fps = _rate(
            ["export", "mcap", str(short), "--out", str(mcap), "--force", *extra], 120, repeats
        )
        rows.append([label, "120", f"{fps:.0f}", f"{mcap.stat().st_size / 120 / 1024:.0f}", ""])
    fps = _rate(["import", "mcap", str(mcap), "--out", str(back), "--force"], 120, repeats)
    rows.append(["import", "120", f"{fps:.0f}", "", ""])
    for n in lengths:
        src = cycled(base, tmp / f"long{n}.h5", n)
        out = tmp / f"long{n}.mcap"
        res = subprocess.run(
            [sys.executable, "-c", PEAK_RSS, str(src), str(out)],
            check=True,
            capture_output=True,
            text=True,
            cwd=ROOT,
        )
        dt_s, rss_kib = res.stdout.split()[-2:]
        dt, rss_mib = float(dt_s), int(rss_kib) / 1024
        rows.append(
            [
                "export, frames only (fresh process)",
                str(n),
                f"{n / dt:.0f}",
                f"{out.stat().st_size / n / 1024:.0f}",
                f"{rss_mib:.0f}",
            ]
        )
        src.unlink()
        out.unlink()
    return table(["run", "frames", "frames/s", "MCAP KiB/frame", "peak RSS MiB"], rows)


class FoxgloveClient(threading.Thread):
    """A Foxglove WebSocket client subscribed to every channel. ``slow``: it reads one
    message every 0.25 s (far below what is published), so the server's backlog for it
    fills and the SDK drops the oldest; ``stall``: it never reads after subscribing.
    Counts the gray images it reads and their age (arrival here - log time)."""

    def __init__(self, url: str, mode: str) -> None:
        super().__init__(daemon=True)
        self.url, self.mode = url, mode
        self.gray_ages_s: list[float] = []
        self.ready = threading.Event()
        self.stop = threading.Event()

    def run(self) -> None:
        from websockets.sync.client import connect

        with connect(self.url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
            channels = {}
            while len(channels) < 13:
                msg = ws.recv(timeout=10)
                if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                    channels.update({c["id"]: c["topic"] for c in json.loads(msg)["channels"]})
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [{"id": cid, "channelId": cid} for cid in channels],
                    }
                )
            )
            gray = next(c for c, t in channels.items() if t == "/tof/gray")
            self.ready.set()
            while not self.stop.is_set():
                if self.mode == "stall":
                    time.sleep(0.05)
                    continue
                if self.mode == "slow":
                    time.sleep(0.25)
                try:
                    msg = ws.recv(timeout=0.5)
                except TimeoutError:
                    continue
                if isinstance(msg, bytes) and int.from_bytes(msg[1:5], "little") == gray:
                    log_ns = int.from_bytes(msg[5:13], "little")
                    self.gray_ages_s.append(time.time() - log_ns * 1e-9)


def _foxglove_status(port: int) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/foxglove", timeout=2) as r:
        return json.load(r)


def live_table(rate_hz: float, seconds: float, repeats: int) -> str:
    rows = []
    cases = (
        ("off", None),
        ("on, no client", "none"),
        ("on, a client reading", "read"),
        ("on, a client reading 4 messages/s", "slow"),
        ("on, a client that never reads", "stall"),
    )
    bar = tqdm(total=len(cases) * repeats, desc="live foxglove", unit="run", file=sys.stderr)
    for label, client in cases:
        runs = []
        for _ in range(repeats):
            fox_port = free_port()
            env = {"TOFPOSE_FOXGLOVE_PORT": str(fox_port)} if client is not None else {}
            server = Server(rate_hz, env=env)
            fc = None
            try:
                if client in ("read", "slow", "stall"):
                    fc = FoxgloveClient(f"ws://127.0.0.1:{fox_port}", client)
                    fc.start()
                    fc.ready.wait(20)
                time.sleep(1.0)
                before = _foxglove_status(server.port) if client is not None else None
                n_before = len(fc.gray_ages_s) if fc is not None else 0
                t0 = time.monotonic()
                res = asyncio.run(_run(f"ws://127.0.0.1:{server.port}/ws/live", 1, seconds))
                span = time.monotonic() - t0
                after = _foxglove_status(server.port) if client is not None else None
                nan = float("nan")
                pub = nan if before is None else (after["published"] - before["published"]) / span
                got = age = nan
                if fc is not None and fc.mode != "stall":
                    ages = fc.gray_ages_s[n_before:]
                    got = len(ages) / span
                    age = statistics.median(ages) if ages else nan
                runs.append((res[0][0], pub, got, age))
            finally:
                if fc is not None:
                    fc.stop.set()
                server.stop()
            bar.update()
        med = [statistics.median(r[i] for r in runs) for i in range(4)]
        rows.append(
            [
                label,
                f"{rate_hz:g}",
                *(f"{v:.1f}" if v == v else "-" for v in med[:3]),  # NaN -> "-"
                f"{med[3]:.2f}" if med[3] == med[3] else "-",
            ]
        )
    bar.close()
    return table(
        [
            "Foxglove server",
            "camera Hz",
            "poses/s on /ws/live",
            "frames published/s",
            "gray images read/s",
            "their age s (median)",
        ],
        rows,
    )


def rerun_screenshot(out_png: Path, tmp: Path) -> None:
    """Rerun's web viewer on an export of the cluttered scene, in headless chromium."""
    rec, mcap = tmp / "shot.h5", tmp / "shot.mcap"
    assert (
        tofpose(
            [
                "simulate",
                "--scenario",
                "clutter",
                "--frames",
                "12",
                "--out",
                str(rec),
                "--seed",
                "1",
            ]
        )
        == 0
    )
    assert tofpose(["export", "mcap", str(rec), "--out", str(mcap), "--force"]) == 0
    rerun_web_screenshot([mcap], out_png, viewport=(1400, 900), load_s=25.0)
    docs = ROOT / "docs"
    shown = out_png.relative_to(docs) if out_png.is_relative_to(docs) else out_png
    print(f"![Rerun's web viewer on an exported recording (`rerun REC.mcap`)]({shown})")


def main() -> None:
    all_cores()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--screenshot", type=Path)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        print(file_table(args.frames, args.repeats, tmp))
        print()
        print(live_table(args.rate, args.seconds, args.repeats))
        if args.screenshot is not None:
            print()
            rerun_screenshot(args.screenshot.resolve(), tmp)


if __name__ == "__main__":
    main()
