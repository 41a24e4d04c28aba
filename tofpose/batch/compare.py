"""Compare two runs over the same recordings (``tofpose compare``): two pipeline
versions, two calibrations, ``estimate`` against ``reprocess``.

A run is a CSV of ``tofpose estimate`` or a directory of ``tofpose reprocess`` (its
``<recording>.csv`` files, paired by name). Per frame where both have a pose: the
attitude difference (angle of R_b R_a^T from the quaternions, deg), the position
difference (mm) and the shift B - A of each position and Euler component; per recording:
poses in each run, gained and lost, the differences' p50 / p95 / max and the mean shift.
Writes ``compare.csv`` (per frame), ``compare.json`` (per recording) and ``compare.png``.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from scipy.spatial.transform import Rotation

SHIFTS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")


class CompareError(ValueError):
    """Runs that cannot be compared; the message says which file and why."""


def _runs(path: str) -> dict[str, Path]:
    p = Path(path)
    if p.is_file():
        return {p.stem: p}
    if p.is_dir():
        found = {c.stem: c for c in sorted(p.glob("*.csv")) if c.name != "compare.csv"}
        if found:
            return found
        raise CompareError(f"{p}: a directory without CSVs of estimate or reprocess")
    raise CompareError(f"{p}: no such file or directory")


def _read(path: Path) -> dict[str, np.ndarray]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise CompareError(f"{path}: cannot read ({exc.strerror})") from exc
    need = (
        "frame",
        "ok",
        "x_mm",
        "y_mm",
        "z_mm",
        "qw",
        "qx",
        "qy",
        "qz",
        "pitch_deg",
        "yaw_deg",
        "roll_deg",
    )
    if not rows or any(k not in rows[0] for k in need):
        missing = [k for k in need if not rows or k not in rows[0]]
        raise CompareError(f"{path}: not a pose CSV (missing column {missing[0]})")

    def col(k: str) -> np.ndarray:
        return np.array([float(r[k]) if r[k] != "" else math.nan for r in rows])

    out = {k: col(k) for k in need}
    out["ok"] = out["ok"] > 0
    return out


def _stats(x: np.ndarray) -> dict[str, float | None]:
    if not len(x):
        return {"p50": None, "p95": None, "max": None}
    return {
        "p50": round(float(np.median(x)), 6),
        "p95": round(float(np.percentile(x, 95)), 6),
        "max": round(float(np.max(x)), 6),
    }


def compare_runs(run_a: str, run_b: str, out_dir: str | Path) -> dict:
    """Compare (module docstring); returns compare.json's content."""
    a_runs, b_runs = _runs(run_a), _runs(run_b)
    if Path(run_a).is_file() and Path(run_b).is_file():
        pairs = {
            a_runs[next(iter(a_runs))].stem: (
                next(iter(a_runs.values())),
                next(iter(b_runs.values())),
            )
        }
    else:
        common = sorted(set(a_runs) & set(b_runs))
        if not common:
            raise CompareError(f"{run_a} and {run_b} share no recording's CSV")
        pairs = {k: (a_runs[k], b_runs[k]) for k in common}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    recordings: dict[str, dict[str, Any]] = {}
    summary: dict[str, Any] = {"run_a": str(run_a), "run_b": str(run_b), "recordings": recordings}
    per_frame = []
    curves = {}
    for name, (pa, pb) in pairs.items():
        a, b = _read(pa), _read(pb)
        if len(a["frame"]) != len(b["frame"]) or not np.array_equal(a["frame"], b["frame"]):
            raise CompareError(
                f"{pa} and {pb} hold different frames ({len(a['frame'])} and {len(b['frame'])})"
            )
        both = a["ok"] & b["ok"]
        att = np.full(len(both), np.nan)
        if both.any():  # angle of R_b R_a^T, stable near 0 (quaternions normalised)
            qa, qb = (
                Rotation.from_quat(np.stack([q[k][both] for k in ("qx", "qy", "qz", "qw")], axis=1))
                for q in (a, b)
            )
            att[both] = np.degrees((qb * qa.inv()).magnitude())
        shift = {k: b[k] - a[k] for k in SHIFTS}
        for k in ("pitch_deg", "yaw_deg", "roll_deg"):
            shift[k] = (shift[k] + 180.0) % 360.0 - 180.0
        pos = np.sqrt(shift["x_mm"] ** 2 + shift["y_mm"] ** 2 + shift["z_mm"] ** 2)
        recordings[name] = {
            "frames": int(len(a["frame"])),
            "ok_a": int(a["ok"].sum()),
            "ok_b": int(b["ok"].sum()),
            "gained": int((~a["ok"] & b["ok"]).sum()),
            "lost": int((a["ok"] & ~b["ok"]).sum()),
            "attitude_diff_deg": _stats(att[both]),
            "position_diff_mm": _stats(pos[both]),
            "mean_shift": {
                k: (round(float(np.mean(v[both])), 6) if both.any() else None)
                for k, v in shift.items()
            },
        }
        curves[name] = (a["frame"][both], att[both], pos[both])
        for i in range(len(a["frame"])):
            per_frame.append(
                [name, int(a["frame"][i]), int(a["ok"][i]), int(b["ok"][i])]
                + (
                    [f"{att[i]:.6f}", f"{pos[i]:.4f}"] + [f"{shift[k][i]:.5f}" for k in SHIFTS]
                    if both[i]
                    else [""] * 8
                )
            )
    with open(out / "compare.csv", "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(
            [
                "recording",
                "frame",
                "ok_a",
                "ok_b",
                "attitude_diff_deg",
                "position_diff_mm",
                *[f"d_{k}" for k in SHIFTS],
            ]
        )
        wr.writerows(per_frame)
    (out / "compare.json").write_text(json.dumps(summary, indent=2))
    fig = Figure(figsize=(11, 3.8))
    ax1, ax2 = fig.subplots(1, 2)
    for name, (f, att, pos) in curves.items():
        ax1.plot(f, att, ".", ms=3, label=name)
        ax2.plot(f, pos, ".", ms=3, label=name)
    ax1.set_ylabel("attitude difference B vs A (deg)")
    ax2.set_ylabel("position difference B vs A (mm)")
    for ax in (ax1, ax2):
        ax.set_xlabel("frame")
        ax.grid(alpha=0.3)
    ax2.legend(fontsize=7)
    fig.suptitle(f"{Path(run_b).name} against {Path(run_a).name}")
    fig.tight_layout()
    fig.savefig(out / "compare.png", dpi=100)
    return summary
