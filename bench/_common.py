"""Benchmark helpers: pin to one core, single-threaded OpenCV, table printing."""

from __future__ import annotations

import os

import numpy as np


def single_core() -> None:
    """Pin this process to one core and keep OpenCV single-threaded."""
    import cv2

    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)


def all_cores() -> None:
    """Undo an inherited one-core pin (``make bench`` runs this after benches that pin
    themselves with ``single_core``): the server, its clients and the browsers share the
    machine's cores, as in use; pinned, a 30 Hz camera fell to 10 Hz."""
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, range(os.cpu_count() or 1))


def table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    line = "| " + " | ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    body = [
        "| " + " | ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) + " |" for r in rows
    ]
    return "\n".join([line, sep, *body])


def med_p95(values) -> tuple[float, float]:
    v = np.asarray(values, float)
    return float(np.median(v)), float(np.percentile(v, 95))


def pose_errors(R_est, t_est, T_true) -> tuple[float, float]:
    """(position error mm, geodesic attitude error deg) of an estimate against a truth."""
    from tofpose.core.geometry import rotation_angle_deg

    return float(np.linalg.norm(np.asarray(t_est) - T_true.t_mm)), rotation_angle_deg(
        T_true.R, np.asarray(R_est)
    )


def relative_euler_deg(R) -> np.ndarray:
    """(pitch, yaw, roll) deg of R relative to the facing reference (face-on reads ~0
    like the paper's tables): ``tofpose.core.geometry.facing_euler_deg``."""
    from tofpose.core.geometry import facing_euler_deg

    return facing_euler_deg(np.asarray(R))


def stats(values) -> dict[str, float]:
    """median, RMS and 95th percentile of finite values (NaN when none)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"median": np.nan, "rms": np.nan, "p95": np.nan}
    return {
        "median": float(np.median(v)),
        "rms": float(np.sqrt(np.mean(v**2))),
        "p95": float(np.percentile(v, 95)),
    }


def fmt(x: float, digits: int = 2) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{digits}f}"


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, dpi: int = 100) -> None:
    """Lay out, write to ``path`` (PNG) and close a figure."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)


def section_main(doc: str, default_frames: int, run, plot, markdown, image_name: str) -> None:
    """Command line of a one-plot benchmark section: ``--frames N --out DIR``; runs
    ``run(frames)``, saves ``plot(data, path)`` and prints ``markdown(data, path, frames)``."""
    import argparse
    from pathlib import Path

    ap = argparse.ArgumentParser(description=doc)
    ap.add_argument("--frames", type=int, default=default_frames)
    ap.add_argument("--out", default="docs/img/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = run(args.frames)
    img = out / image_name
    plot(data, img)
    print(markdown(data, str(img), args.frames))


def free_port() -> int:
    """A free TCP port on loopback (for a server the bench starts)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
