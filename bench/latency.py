"""Live latency and dropped frames per camera source (issue 46, item 3).

For each source, starts ``tofpose serve`` (no 3-D scene, no motion system but the
simulator's) in a subprocess, waits for its compiled pipeline, then reads /ws/live for
``--seconds`` with one client that reads everything (poses only, as a GNC loop would
subscribe) and tabulates, per frame, the server's stamps (capture, arrival, pose ready,
sent; host monotonic ns) and the moment this client received the message (the same
host's monotonic clock: the bench runs beside the server). Sources:

- ``sim``: the simulated camera (capture = the render's lab time on the host's clock);
- ``tofcam660``: the TOFcam-660 driver against the project's emulator served from this
  process on a loopback address (capture = the acquisition command sent; the emulator
  renders with the simulator, then sends the image over UDP);
- ``replay``: a recording made with ``tofpose simulate`` (stability-5712), played back
  at 10 frames/s (capture = the recorded stamp mapped to playback).

Prints the median and 95th percentile (ms) of each stage and the frames dropped (camera,
pipeline, this client) over the run, and the server's own ``/api/live/stats`` at the end.

Run: ``python bench/latency.py [--sources sim tofcam660 replay] [--seconds 20] [--rate 10]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import all_cores, table  # noqa: E402
from bench._serve import start_serve, stop_serve  # noqa: E402

EMULATOR_ADDRESS = "127.0.0.47"


class Server:
    """``tofpose serve`` on a free port with a fresh data directory and ``camera``."""

    def __init__(self, camera: str, rate_hz: float, data_dir: Path) -> None:
        env = {
            "TOFPOSE_CAMERA": camera,
            "TOFPOSE_MOTION": "sim" if camera == "sim" else "none",
            "TOFPOSE_FRAME_RATE_HZ": str(rate_hz),
            "TOFPOSE_DATA_DIR": str(data_dir),
        }
        if camera.startswith("replay:"):
            env["TOFPOSE_REPLAY_RATE_HZ"] = str(rate_hz)
        self.proc, self.port = start_serve(env, camera, poll_timeout_s=5.0)

    def get(self, path: str) -> dict:
        with urllib.request.urlopen(f"http://127.0.0.1:{self.port}{path}", timeout=5) as r:
            return json.load(r)

    def stop(self) -> None:
        stop_serve(self.proc)


def read_poses(port: int, seconds: float) -> list[tuple[dict, int]]:
    """(pose message, received monotonic ns) for every pose message over ``seconds``
    (after 2 s of warm-up)."""
    from websockets.sync.client import connect

    out = []
    with connect(f"ws://127.0.0.1:{port}/ws/live", max_size=None) as ws:
        ws.recv()  # hello
        start = time.monotonic()
        while time.monotonic() - start < seconds + 2.0:
            text = ws.recv()
            received_ns = time.monotonic_ns()
            m = json.loads(text)
            if m.get("type") == "pose" and time.monotonic() - start >= 2.0:
                out.append((m, received_ns))
    return out


STAGES = (
    ("capture -> arrival", "capture_ns", "arrival_ns"),
    ("arrival -> pose ready", "arrival_ns", "pose_ready_ns"),
    ("pose ready -> sent", "pose_ready_ns", "sent_ns"),
    ("sent -> received", "sent_ns", "received_ns"),
    ("capture -> pose ready", "capture_ns", "pose_ready_ns"),
    ("capture -> sent", "capture_ns", "sent_ns"),
    ("capture -> received", "capture_ns", "received_ns"),
)


def stage_ms(poses: list[tuple[dict, int]]) -> dict[str, np.ndarray]:
    rows = [
        {**m["stamps"], "sent_ns": m["sent_ns"], "received_ns": rx}
        for m, rx in poses
        if m.get("stamps")
    ]
    return {name: np.array([(r[b] - r[a]) / 1e6 for r in rows], float) for name, a, b in STAGES}


def make_recording(path: Path) -> None:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "tofpose.cli",
            "simulate",
            "--scenario",
            "stability-5712",
            "--frames",
            "60",
            "--out",
            str(path),
        ],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def run_source(source: str, seconds: float, rate_hz: float, tmp: Path) -> dict:
    emulator = None
    if source == "sim":
        camera = "sim"
    elif source == "tofcam660":
        from backend.drivers.sim import make_sim_world
        from backend.emulators.tofcam660 import TofCam660Emulator

        world = make_sim_world(start_rail_mm=13000.0)
        emulator = TofCam660Emulator(world, EMULATOR_ADDRESS)
        emulator.start()
        camera = f"tofcam660:{EMULATOR_ADDRESS}"
    else:
        rec = tmp / "replay.h5"
        if not rec.exists():
            make_recording(rec)
        camera = f"replay:{rec}"
    data = tmp / f"data-{source}"
    data.mkdir(exist_ok=True)
    try:
        server = Server(camera, rate_hz, data)
        try:
            poses = read_poses(server.port, seconds)
            stats = server.get("/api/live/stats")
        finally:
            server.stop()
    finally:
        if emulator is not None:
            emulator.close()
    first, last = poses[0][0], poses[-1][0]
    idx = [m["data"]["frame_index"] for m, _ in poses]
    return {
        "source": source,
        "frames": len(poses),
        "fps": (len(poses) - 1) / ((poses[-1][1] - poses[0][1]) / 1e9),
        "ms": stage_ms(poses),
        "dropped": {
            k: (last["latency"]["dropped_total"][k] or 0)
            - (first["latency"]["dropped_total"][k] or 0)
            for k in ("camera", "pipeline")
        }
        | {"this client": last["dropped"] - first["dropped"]},
        "frame_gaps": int(sum(b - a - 1 for a, b in zip(idx, idx[1:], strict=False))),
        "capture_source": stats["capture_source"],
        "stats": stats,
    }


def report(results: list[dict], seconds: float, rate_hz: float) -> str:
    lines = [
        f"Live latency per camera source, {seconds:g} s each at {rate_hz:g} frames/s, one "
        "client reading every pose message (ms, median / 95th percentile):",
        "",
    ]
    header = ["stage", *[r["source"] for r in results]]
    rows = []
    for name, _, _ in STAGES:
        row = [name]
        for r in results:
            v = r["ms"][name]
            row.append(f"{np.median(v):.1f} / {np.percentile(v, 95):.1f}" if v.size else "-")
        rows.append(row)
    rows.append(["frames received", *[str(r["frames"]) for r in results]])
    rows.append(["frames/s", *[f"{r['fps']:.1f}" for r in results]])
    for k in ("camera", "pipeline", "this client"):
        rows.append([f"dropped: {k}", *[str(r["dropped"][k]) for r in results]])
    lines.append(table(header, rows))
    lines.append("")
    lines.append("What capture means on each source:")
    lines.append("")
    for r in results:
        lines.append(f"- {r['source']}: {r['capture_source']}")
    lines.append("")
    ncpu = os.cpu_count()
    load = os.getloadavg()[0]
    lines.append(
        f"Machine: {ncpu} cores, load average {load:.1f} at the end (shared with other work)."
    )
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sources", nargs="+", default=["sim", "tofcam660", "replay"])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--rate", type=float, default=10.0)
    args = p.parse_args()
    all_cores()
    with tempfile.TemporaryDirectory() as tmp:
        results = [run_source(s, args.seconds, args.rate, Path(tmp)) for s in args.sources]
    print(report(results, args.seconds, args.rate))


if __name__ == "__main__":
    main()
