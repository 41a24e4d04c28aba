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
