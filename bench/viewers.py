"""A campaign as a lab would open it in Rerun: the pictures of docs/interop.md.

Starts a server on the simulated bench, runs a small campaign with ``record_raw`` (a yaw
sweep, so the target moves in the camera frame and the turntable's channels change),
downloads its recording, exports it with ``tofpose export mcap`` (which writes the
Foxglove layout and the Rerun blueprint beside it) and ``tofpose export rrd``, prints
what the MCAP holds (frames, encoder and set-point messages, their wall-clock span) and
takes Rerun's web viewer on each in headless chromium (software rendering):

    python bench/viewers.py [--shots docs/img/interop]

Needs rerun-sdk (its ``rerun`` viewer) and Debian's chromium.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import urllib.request
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._rerun_web import rerun_web_screenshot  # noqa: E402
from bench.live import Server  # noqa: E402
from tofpose.cli import main as tofpose  # noqa: E402
from tofpose.io.interop import topics  # noqa: E402

TOKEN = "bench-viewers-token-0123456789"
YAWS_DEG = (-6.0, -3.0, 0.0, 3.0, 6.0)


def _request(server: Server, method: str, path: str, body: dict | None = None) -> bytes:
    req = urllib.request.Request(
        f"http://127.0.0.1:{server.port}{path}",
        method=method,
        data=None if body is None else json.dumps(body).encode(),
        headers={"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"},
    )
    with urllib.request.urlopen(req, timeout=600) as r:
        return r.read()


def record_campaign(out_h5: Path) -> int:
    """Run the yaw sweep with ``record_raw`` on a fresh server; its recording -> out_h5."""
    server = Server(10.0, env={"TOFPOSE_API_TOKEN": TOKEN, "TOFPOSE_SIM_TIME_SCALE": "3"})
    try:
        body = {
            "name": "viewers",
            "catalog": "paper-target",
            "frames_per_point": 8,
            "settle_s": 0.3,
            "record_raw": True,
            "setpoints": [{"yaw_deg": y, "rail_mm": 12000.0} for y in YAWS_DEG],
        }
        cid = json.loads(_request(server, "POST", "/api/campaigns", body))["id"]
        _request(server, "POST", f"/api/campaigns/{cid}/start")
        deadline = time.monotonic() + 600
        while json.loads(_request(server, "GET", f"/api/campaigns/{cid}"))["status"] != "done":
            if time.monotonic() > deadline:
                raise RuntimeError("the campaign did not finish in 10 min")
            time.sleep(1.0)
        out_h5.write_bytes(_request(server, "GET", f"/api/campaigns/{cid}/recording.h5"))
        return cid
    finally:
        server.stop()


def mcap_summary(mcap: Path) -> str:
    """Frames, turntable messages and their wall-clock span, as the mcap reader sees them."""
    from mcap.reader import make_reader

    counts: dict[str, int] = {}
    times: list[int] = []
    with open(mcap, "rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == topics.ENCODERS:
                times.append(message.log_time)
    first, last = (datetime.fromtimestamp(t / 1e9, UTC) for t in (min(times), max(times)))
    return (
        f"{counts[topics.GRAY]} frames; {counts[topics.ENCODERS]} encoder and "
        f"{counts[topics.SETPOINT]} set-point messages from {first:%Y-%m-%d %H:%M:%S} to "
        f"{last:%H:%M:%S} UTC; {counts.get(topics.TARGET_ORIGIN, 0)} trail points"
    )


def rerun_screenshot(files: list[Path], out_png: Path) -> None:
    """Rerun's web viewer on ``files`` (a recording and a blueprint), 1366 x 768."""
    rerun_web_screenshot(files, out_png, viewport=(1366, 768), load_s=30.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--shots", type=Path, help="directory for rerun-mcap.png, rerun-rrd.png")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        h5 = tmp / "campaign.h5"
        cid = record_campaign(h5)
        mcap, rrd = tmp / f"campaign-{cid}.mcap", tmp / f"campaign-{cid}.rrd"
        assert tofpose(["export", "mcap", str(h5), "--out", str(mcap)]) == 0
        assert tofpose(["export", "rrd", str(h5), "--out", str(rrd)]) == 0
        print(mcap_summary(mcap))
        if args.shots is not None:
            shots = args.shots.resolve()
            rerun_screenshot([mcap, mcap.with_suffix(".rbl")], shots / "rerun-mcap.png")
            rerun_screenshot([rrd], shots / "rerun-rrd.png")
            print(f"Rerun's web viewer: {shots / 'rerun-mcap.png'}, {shots / 'rerun-rrd.png'}")


if __name__ == "__main__":
    main()
