"""A campaign's camera settings and metadata in its report (docs/campaigns.md, "Camera
settings and metadata").

When the campaign varies the camera (set-points with different integration times or
modulation frequencies), the frames are grouped by their set-point's setting and each
group gets: set-points, frames, frames with a pose (success), the range error (measured
minus reference distance from the camera to the target origin, mm: mean and 1 sigma over
every frame with a pose, no outlier removal), the z error's mean and 1 sigma, and
whether every set-point of the group passed. A plot shows the range error (mean +/- 1
sigma) and the success against the integration time.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from backend.services.reports.analysis import REFERENCE_PREFIX
from backend.services.reports.report_content import Table, fmt, setting_text
from backend.services.reports.report_plots import Plot, Rect, axes_grid

if TYPE_CHECKING:
    from matplotlib.figure import Figure

SETTING_COLUMNS = {
    "integration_time_us": "setpoint_integration_time_us",
    "modulation_frequency_mhz": "setpoint_modulation_frequency_mhz",
}
METADATA_LABELS = (
    ("operator", "operator"),
    ("target_name", "target"),
    ("camera_model", "camera"),
    ("camera_serial", "serial"),
    ("camera_firmware", "firmware"),
)


def row_setting(row: dict) -> dict[str, float]:
    """The camera setting a frame's set-point commanded ({} for none)."""
    return {k: float(row[c]) for k, c in SETTING_COLUMNS.items() if row.get(c) is not None}


def _key(setting: dict[str, float]) -> tuple[float, float]:
    return (
        setting.get("integration_time_us", -1.0),
        setting.get("modulation_frequency_mhz", -1.0),
    )


def _range_mm(rows: list[dict], prefix: str) -> np.ndarray:
    xyz = np.array(
        [
            [
                np.nan if r[prefix + a] is None else float(r[prefix + a])
                for a in ("x_mm", "y_mm", "z_mm")
            ]
            for r in rows
        ],
        float,
    ).reshape(-1, 3)
    return np.linalg.norm(xyz, axis=1)


def _mean_std(v: np.ndarray) -> tuple[float, float]:
    v = v[np.isfinite(v)]
    mean = float(np.mean(v)) if v.size else float("nan")
    std = float(np.std(v, ddof=1)) if v.size > 1 else float("nan")
    return mean, std


def camera_groups(rows: list[dict], setpoints: list[dict], reference: str) -> list[dict] | None:
    """Statistics per camera setting (see module), ordered by integration time then
    modulation; None when the campaign does not vary the camera. ``setpoints``: the
    report's per-set-point entries (their ``passed``)."""
    by_setting: dict[tuple[float, float], list[dict]] = {}
    settings: dict[tuple[float, float], dict[str, float]] = {}
    for r in rows:
        s = row_setting(r)
        by_setting.setdefault(_key(s), []).append(r)
        settings[_key(s)] = s
    if len(by_setting) < 2:
        return None
    passed = {sp["setpoint_index"]: sp["passed"] for sp in setpoints}
    prefix = REFERENCE_PREFIX[reference]
    out = []
    for key in sorted(by_setting):
        group = by_setting[key]
        ok = [r for r in group if r["ok"] and r["x_mm"] is not None]
        range_err = _range_mm(ok, "") - _range_mm(ok, prefix)
        z_err = np.array(
            [
                np.nan
                if r[prefix + "z_mm"] is None
                else float(r["z_mm"]) - float(r[prefix + "z_mm"])
                for r in ok
            ],
            float,
        )
        indices = sorted({int(r["setpoint_index"]) for r in group})
        verdicts = [passed.get(i) for i in indices]
        mean, std = _mean_std(range_err)
        z_mean, z_std = _mean_std(z_err)
        out.append(
            {
                "setting": settings[key],
                "setpoints": indices,
                "n_frames": len(group),
                "n_ok": len(ok),
                "success_rate": len(ok) / len(group),
                "range_error_mean_mm": mean,
                "range_error_std_mm": std,
                "z_error_mean_mm": z_mean,
                "z_error_std_mm": z_std,
                "passed": None if None in verdicts else all(verdicts),
            }
        )
    return out


def camera_table(report: dict) -> Table:
    """One row per camera setting: its set-points, frames with a pose, range and z error
    mean and 1 sigma, and the result of its set-points."""
    header = [
        "camera setting",
        "set-points",
        "frames with a pose",
        "range error mean (mm)",
        "range error 1 sigma (mm)",
        "z error mean (mm)",
        "z error 1 sigma (mm)",
        "result",
    ]
    rows, status = [], {}
    for i, g in enumerate(report.get("camera_settings") or []):
        rows.append(
            [
                setting_text(g["setting"]),
                str(len(g["setpoints"])),
                f"{g['n_ok']} of {g['n_frames']} ({100.0 * g['success_rate']:.0f} %)",
                fmt(g["range_error_mean_mm"]),
                fmt(g["range_error_std_mm"]),
                fmt(g["z_error_mean_mm"]),
                fmt(g["z_error_std_mm"]),
                fmt(g["passed"]),
            ]
        )
        if g["passed"] is not None:
            status[(i, 7)] = g["passed"]
    caption = (
        "Range error = measured minus reference distance from the camera to the target, "
        "over every frame with a pose (no outlier removal)"
    )
    return Table(header, rows, status, caption)


def metadata_text(report: dict) -> str:
    """``operator A; target T; camera M; serial S; firmware F; notes: N`` (fields not
    given say so)."""
    c = report["campaign"]
    parts = [f"{label} {c.get(key) or 'not given'}" for key, label in METADATA_LABELS]
    text = "; ".join(parts)
    text = text[:1].upper() + text[1:]
    notes = (c.get("notes") or "").strip()
    return f"{text}. Notes: {notes}" if notes else f"{text}. No notes."


def draw_range_error_vs_setting(report: dict) -> Callable[[Figure, Rect], None]:
    """Range error mean +/- 1 sigma (left) and frames with a pose (right) against the
    integration time, one series per modulation frequency."""

    def draw(fig: Figure, rect: Rect) -> None:
        groups = [g for g in report["camera_settings"] if "integration_time_us" in g["setting"]]
        err_ax, ok_ax = axes_grid(fig, rect, 1, 2, "Range error and success vs integration time")[0]
        by_mod: dict[float | None, list[dict]] = {}
        for g in groups:
            by_mod.setdefault(g["setting"].get("modulation_frequency_mhz"), []).append(g)
        for mod, gs in by_mod.items():
            t = np.array([g["setting"]["integration_time_us"] for g in gs], float)
            mean, std = (
                np.array([np.nan if g[k] is None else g[k] for g in gs], float)
                for k in ("range_error_mean_mm", "range_error_std_mm")
            )
            label = f"{mod:g} MHz" if mod is not None else None
            err_ax.errorbar(
                t, mean, yerr=np.nan_to_num(std), fmt="o-", ms=4, capsize=3, label=label
            )
            ok_ax.plot(t, [100.0 * g["success_rate"] for g in gs], "s-", ms=4, label=label)
        ticks = sorted({g["setting"]["integration_time_us"] for g in groups})
        for ax in (err_ax, ok_ax):
            ax.set_xscale("log")
            ax.set_xticks(ticks, [f"{v:g}" for v in ticks])
            ax.minorticks_off()
            ax.set_xlabel("integration time (us, log scale)", fontsize=8)
            if len(by_mod) > 1:
                ax.legend(fontsize=7, title="modulation", title_fontsize=7)
        err_ax.axhline(0.0, color="k", lw=0.6)
        err_ax.set_ylabel("range error, mean +/- 1 sigma (mm)", fontsize=8)
        ok_ax.set_ylabel("frames with a pose (%)", fontsize=8)
        ok_ax.set_ylim(0.0, 105.0)

    return draw


def camera_plots(report: dict) -> list[Plot]:
    """The range-error plot when the campaign varied the integration time, else none."""
    groups = report.get("camera_settings") or []
    times = {g["setting"].get("integration_time_us") for g in groups} - {None}
    if len(times) < 2:
        return []
    return [Plot("Range error vs integration time", draw_range_error_vs_setting(report), 2.8, 4.2)]
