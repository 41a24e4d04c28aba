"""The pixel-level fit in the live loop (``TOFPOSE_PIXEL_FIT``): what it costs a live user.

Starts ``tofpose serve`` (simulated lab, the camera at ``--rate`` Hz) with the target at
each range (``TOFPOSE_SIM_START_RAIL_MM``), with the pixel fit off and on, waits until
the compiled pipeline measures, then reads the live WebSocket for ``--seconds``: ok poses
per second delivered, the latency from the frame reaching the server to its receipt
(median, p95), the share of ok poses the fit refined (``pixel_fit`` "ok"; else it fell
back and said why), the fit's ms a frame (``timings_ms``), and the reported attitude and
position sigmas (median of the 3-D sigma: sqrt of the sum of the per-axis variances).
Each setting is repeated; the table gives medians over repeats. The pipeline runs on the
server's acquisition thread, one core; a loop slower than the camera measures the newest
frame each time (docs/server.md), so a costly fit shows as fewer poses a second.

Run: ``python bench/live_pixel_fit.py [--ranges 1 2 3 6] [--rate 10] [--seconds 8]
[--repeats 2]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import websockets

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import table  # noqa: E402
from bench.live import Server, pose_messages  # noqa: E402

#: the simulated lab's target sits this far from the camera at rail 0 (mm)
TARGET_AT_RAIL_0_MM = 15000.0


def _get(port: int, path: str) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as r:
        return json.load(r)


def _wait_compiled(port: int, timeout_s: float = 180.0) -> None:
    """Until the live pipeline is the compiled one (the first seconds measure with the
    reference implementation while the kernels load)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        p = _get(port, "/api/health")["pipeline"]
        if p["state"] == "ready" and p["implementation"] == "compiled":
            return
        time.sleep(0.5)
    raise RuntimeError("the compiled pipeline did not start")


async def _listen(port: int, seconds: float) -> dict:
    """One client on /ws/live for ``seconds`` after 2 s of settling: the measures of the
    module docstring."""
    url = f"ws://127.0.0.1:{port}/ws/live"
    ok_t, lat_ms, fit_ms, att, pos, held, n_ok = [], [], [], [], [], 0, 0
    async with websockets.connect(url, max_queue=64, close_timeout=1) as ws:
        t_settle = time.monotonic() + 2.0
        async for now, d in pose_messages(ws, t_settle + seconds):
            if time.monotonic() < t_settle or not d["ok"]:
                continue
            n_ok += 1
            ok_t.append(time.monotonic())
            lat_ms.append(1e3 * (now - d["captured_unix_s"]))
            if d.get("pixel_fit") == "ok":
                held += 1
            if "pixel fit" in d["timings_ms"]:
                fit_ms.append(d["timings_ms"]["pixel fit"])
            if d.get("attitude_sigma_deg") and d.get("position_sigma_mm"):
                att.append(float(np.linalg.norm(d["attitude_sigma_deg"])))
                pos.append(float(np.linalg.norm(d["position_sigma_mm"])))
    span = ok_t[-1] - ok_t[0] if len(ok_t) > 1 else np.nan
    return {
        "poses_s": (len(ok_t) - 1) / span if len(ok_t) > 1 else 0.0,
        "lat_p50": float(np.median(lat_ms)) if lat_ms else np.nan,
        "lat_p95": float(np.percentile(lat_ms, 95)) if lat_ms else np.nan,
        "held": held / n_ok if n_ok else np.nan,
        "fit_ms": float(np.median(fit_ms)) if fit_ms else np.nan,
        "att_sigma": float(np.median(att)) if att else np.nan,
        "pos_sigma": float(np.median(pos)) if pos else np.nan,
    }


def measure(range_m: float, pixel_fit: bool, rate_hz: float, seconds: float) -> dict:
    env = {
        "TOFPOSE_PIXEL_FIT": "true" if pixel_fit else "false",
        "TOFPOSE_SIM_START_RAIL_MM": str(TARGET_AT_RAIL_0_MM - 1000.0 * range_m),
    }
    srv = Server(rate_hz, env=env)
    try:
        _wait_compiled(srv.port)
        return asyncio.run(_listen(srv.port, seconds))
    finally:
        srv.stop()


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranges", type=float, nargs="+", default=[1.0, 2.0, 3.0, 6.0])
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    rows = []
    for z in args.ranges:
        for on in (False, True):
            runs = [measure(z, on, args.rate, args.seconds) for _ in range(args.repeats)]
            m = {k: float(np.nanmedian([r[k] for r in runs])) for k in runs[0]}
            rows.append(
                [
                    f"{z:g} m",
                    "on" if on else "off",
                    f"{m['poses_s']:.1f}",
                    f"{m['lat_p50']:.0f} / {m['lat_p95']:.0f}",
                    "-" if not on else f"{100 * m['held']:.0f} %",
                    "-" if not on else f"{m['fit_ms']:.0f}",
                    f"{m['att_sigma']:.3f}",
                    f"{m['pos_sigma']:.2f}",
                ]
            )
            print(" | ".join(rows[-1]), file=sys.stderr, flush=True)  # progress
    title = (
        f"the simulated lab's camera at {args.rate:g} Hz, {args.seconds:g} s per run, "
        f"medians over {args.repeats} runs (a fresh server each)"
    )
    text = (
        title
        + "\n\n"
        + table(
            [
                "range",
                "pixel fit",
                "ok poses/s",
                "latency ms (median / p95)",
                "fit held",
                "fit ms (median)",
                "attitude sigma deg (median)",
                "position sigma mm (median)",
            ],
            rows,
        )
    )
    print(text)
    return text


if __name__ == "__main__":
    main()
