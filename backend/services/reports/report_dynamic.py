"""The dynamic section of a campaign report as tables, sentences and plots (the HTML and
the PDF show the same); the numbers come from ``dynamic_analysis``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from backend.services.reports.report_content import Table, fmt
from backend.services.reports.report_plots import Plot, Rect, axes_grid

if TYPE_CHECKING:
    from matplotlib.figure import Figure

ANGLE_NAMES = {"pitch_deg": "pitch", "yaw_deg": "yaw", "roll_deg": "roll"}
MAX_PLOTTED_SETPOINTS = 6


def _ms(v) -> str:
    return "-" if v is None else f"{1000.0 * v:.1f}"


def _pct(v) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{100.0 * v:.1f} %"


def dynamic_tables(report: dict) -> list[Table]:
    """Per dynamic set-point: frames and loss in motion, attitude RMS / max in motion and
    at rest, rate error, latency."""
    dyn = report.get("dynamic")
    if not dyn:
        return []
    att_rows, rate_rows = [], []
    for k, s in dyn["setpoints"].items():
        lat = s.get("latency", {})
        rate = s.get("rate", {})
        att_rows.append(
            [
                str(k),
                str(s["n_in_motion"]),
                _pct(s.get("lost_in_motion_share")),
                *(
                    f"{fmt(s[a]['rms_in_motion'])} / {fmt(s[a]['max_in_motion'])}"
                    for a in ANGLE_NAMES
                ),
                *(f"{fmt(s[a]['rms_at_rest'])} / {fmt(s[a]['max_at_rest'])}" for a in ANGLE_NAMES),
            ]
        )
        rate_rows.append(
            [
                str(k),
                fmt(rate.get("peak_reference_deg_s")),
                fmt(rate.get("rms_error_in_motion_deg_s")),
                _pct(rate.get("rms_error_share_of_peak")),
                fmt(rate.get("max_error_in_motion_deg_s")),
                fmt(rate.get("rms_error_at_rest_deg_s")),
                _ms(lat.get("delay_s")),
                _ms(lat.get("sigma_s")),
            ]
        )
    att = Table(
        [
            "set-point",
            "frames in motion",
            "lost in motion",
            *(f"{n} in motion RMS / max (deg)" for n in ANGLE_NAMES.values()),
            *(f"{n} at rest RMS / max (deg)" for n in ANGLE_NAMES.values()),
        ],
        att_rows,
        caption="Attitude error during the profile and at rest around it",
    )
    rate = Table(
        [
            "set-point",
            "peak reference rate (deg/s)",
            "rate error RMS in motion (deg/s)",
            "RMS / peak",
            "rate error max in motion (deg/s)",
            "rate error RMS at rest (deg/s)",
            "latency (ms)",
            "latency 1-sigma (ms)",
        ],
        rate_rows,
        caption="Angular rate of the relative-state filter against the reference's, "
        "and the measurement latency",
    )
    return [att, rate]


def dynamic_findings(report: dict) -> list[str]:
    """Sentences on latency and loss, each only when the numbers are there."""
    dyn = report.get("dynamic")
    if not dyn:
        return []
    out = []
    pooled = dyn.get("latency")
    if pooled is not None:
        out.append(
            f"Measurement latency {1000 * pooled['delay_s']:.1f} +/- "
            f"{1000 * pooled['sigma_s']:.1f} ms (1 sigma, {pooled['n_setpoints']} profile(s)): "
            "a frame's pose is the attitude the reference had that long before its stamp."
        )
        if pooled["n_setpoints"] > 1 and pooled["chi2"] > 3 * pooled["n_setpoints"]:
            out.append(
                f"The profiles' latencies disagree beyond their sigmas (chi-square "
                f"{pooled['chi2']:.1f} for {pooled['n_setpoints'] - 1} degrees of freedom)."
            )
    lost = [
        (k, s["lost_in_motion_share"])
        for k, s in dyn["setpoints"].items()
        if s.get("lost_in_motion_share", 0) > 0
    ]
    if lost:
        worst = max(lost, key=lambda x: x[1])
        out.append(
            f"Frames lost in motion at {len(lost)} profile(s), worst {100 * worst[1]:.1f} "
            f"% at set-point {worst[0]}."
        )
    return out


def dynamic_plots(report: dict) -> list[Plot]:
    """Per dynamic set-point (at most ``MAX_PLOTTED_SETPOINTS``): attitude error over time
    with the profile shaded, and the rate measured against the reference."""
    dyn = report.get("dynamic")
    if not dyn:
        return []
    return [
        Plot(f"Set-point {k}: error and rate during the profile", _draw(report, k, s), 4.0, 6.0)
        for k, s in list(dyn["setpoints"].items())[:MAX_PLOTTED_SETPOINTS]
    ]


def _shade(ax, t: np.ndarray, moving: np.ndarray) -> None:
    if moving.any():
        ax.axvspan(
            t[moving].min(),
            t[moving].max(),
            color="#f0e0b0",
            alpha=0.5,
            lw=0,
            label="profile running",
        )


def _draw(report: dict, k, s: dict) -> Callable[[Figure, Rect], None]:
    def draw(fig: Figure, rect: Rect) -> None:
        ser = s["series"]
        t = np.asarray(ser["t"], float)
        t = t - t[0]
        moving = np.asarray(ser["in_motion"], bool)
        title = f"Set-point {k} against the {report['reference']} reference"
        axs = axes_grid(fig, rect, 2, 1, title, sharex=True)
        ax = axs[0, 0]
        _shade(ax, t, moving)
        for a, name in ANGLE_NAMES.items():
            e = np.asarray(ser["error"][a], dtype=float)
            ax.plot(t, e, ".", ms=2.5, label=name)
        ax.set_ylabel("attitude error (deg)", fontsize=8)
        ax.legend(fontsize=7, loc="upper right", ncols=4)
        ax = axs[1, 0]
        _shade(ax, t, moving)
        comp = s.get("rate", {}).get("component", "y")
        if "rate_reference" in ser:
            ax.plot(
                t,
                np.asarray(ser["rate_reference"], dtype=float),
                "-",
                lw=1.2,
                color="#444444",
                label="reference",
            )
            ax.plot(
                t,
                np.asarray(ser["rate_measured"], dtype=float),
                ".",
                ms=2.5,
                color="#1f5fa8",
                label="filter",
            )
            ax.legend(fontsize=7, loc="upper right", ncols=3)
        ax.set_ylabel(f"rate about camera {comp} (deg/s)", fontsize=8)
        ax.set_xlabel("time from the first frame of the set-point (s)", fontsize=8)

    return draw
