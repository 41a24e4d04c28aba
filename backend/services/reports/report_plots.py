"""The plots of a campaign report, each drawn into a rectangle of a matplotlib figure so
that the PDF can place it on a page beside tables and the HTML can render it alone.

Rectangles are ``(x, y, width, height)`` in inches from the figure's lower left corner.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from backend.services.reports.analysis import AXES, REFERENCE_PREFIX
from backend.services.reports.report_content import (
    AXIS_NAMES,
    AXIS_UNITS,
    axis_label,
    axis_verdicts,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Rect = tuple[float, float, float, float]
NO_PLOTS = "No frame gave a pose yet: nothing to plot."
PASS_COLOUR, FAIL_COLOUR = "#2a7d2a", "#b00000"
TITLE_H_IN = 0.32  # the plot's title above its axes
LEFT_IN, RIGHT_IN, BOTTOM_IN, GAP_X_IN, GAP_Y_IN = 0.75, 0.15, 0.48, 0.85, 0.3


@dataclass
class Plot:
    """A plot of the report: its title, how to draw it, and the heights it reads well at."""

    title: str
    draw: Callable[[Figure, Rect], None]
    min_height_in: float
    max_height_in: float


def _max_n_locator(nbins: int, integer: bool = False):
    """matplotlib's ``MaxNLocator``, imported when a plot is drawn (docs/server.md, "Memory")."""
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(nbins, integer=integer)


def axes_grid(
    fig: Figure,
    rect: Rect,
    nrows: int,
    ncols: int,
    title: str,
    gap_y_in: float = GAP_Y_IN,
    **kw,
):
    """``nrows x ncols`` axes filling ``rect`` below a title (room left for tick labels;
    ``gap_y_in`` between rows, more where every row has its own x label)."""
    x, y, w, h = rect
    fw, fh = fig.get_size_inches()
    fig.text(
        (x + w / 2) / fw,
        (y + h - 0.06) / fh,
        title,
        ha="center",
        va="top",
        fontsize=10.5,
        weight="bold",
    )
    inner_w = w - LEFT_IN - RIGHT_IN
    inner_h = h - TITLE_H_IN - BOTTOM_IN
    cell_w = (inner_w - GAP_X_IN * (ncols - 1)) / ncols
    cell_h = (inner_h - gap_y_in * (nrows - 1)) / nrows
    gs = fig.add_gridspec(
        nrows,
        ncols,
        left=(x + LEFT_IN) / fw,
        right=(x + w - RIGHT_IN) / fw,
        bottom=(y + BOTTOM_IN) / fh,
        top=(y + h - TITLE_H_IN) / fh,
        wspace=GAP_X_IN / max(cell_w, 0.1),
        hspace=gap_y_in / max(cell_h, 0.1),
    )
    axs = gs.subplots(squeeze=False, **kw)
    for ax in axs.ravel():
        ax.tick_params(labelsize=7.5)
        ax.xaxis.set_major_locator(_max_n_locator(6))
        ax.grid(alpha=0.3)
    return axs


def frame_arrays(rows: list[dict], reference: str) -> dict[str, np.ndarray]:
    """Time, set-point and per axis measured and reference values of the frames with a pose."""
    prefix = REFERENCE_PREFIX[reference]
    ok = [r for r in rows if r["ok"]]

    def col(k):
        return np.array([np.nan if r[k] is None else float(r[k]) for r in ok], float)

    out = {"t": col("time_s"), "sp": col("setpoint_index")}
    for a in AXES:
        out[a], out["ref_" + a] = col(a), col(prefix + a)
    return out


def _num(v) -> float:
    return float("nan") if v is None else float(v)


# -- the plots -------------------------------------------------------------------------------
def draw_requirement_share(report: dict) -> Callable[[Figure, Rect], None]:
    """Bars of max |error| / requirement per axis, the requirement at 100 %."""

    def draw(fig: Figure, rect: Rect) -> None:
        verdicts = axis_verdicts(report)
        (ax,) = axes_grid(fig, rect, 1, 1, "max |error| as a share of the requirement")[0]
        share = np.array([100.0 * v.share for v in verdicts])
        colours = [FAIL_COLOUR if v.passed is False else PASS_COLOUR for v in verdicts]
        y = np.arange(len(verdicts))[::-1]
        ax.barh(y, np.nan_to_num(share), color=colours, height=0.6)
        ax.axvline(100.0, color="k", lw=1.0, ls="--")
        ax.set_yticks(y, [AXIS_NAMES[v.axis] for v in verdicts], fontsize=8)
        top = max(120.0, float(np.nanmax(np.r_[share, 0.0])) * 1.25)
        ax.set_xlim(0.0, top)
        ax.set_xlabel("max |error| / requirement (%); dashed: the requirement", fontsize=8)
        for yi, s in zip(y, share, strict=True):
            if np.isfinite(s):
                ax.text(s + top * 0.01, yi, f"{s:.0f} %", va="center", fontsize=7.5)
        ax.grid(axis="y", alpha=0.0)

    return draw


def draw_error_series(report: dict, d: dict) -> Callable[[Figure, Rect], None]:
    """Error per frame over time, one panel per axis (the paper's Figs. 8-10)."""

    def draw(fig: Figure, rect: Rect) -> None:
        title = f"Error per frame against the {report['reference']} reference"
        axs = axes_grid(fig, rect, 3, 2, title, sharex=True)
        for ax, a in zip(axs.T.ravel(), AXES, strict=True):
            ax.plot(d["t"], d[a] - d["ref_" + a], ".", ms=2)
            ax.set_ylabel(f"{AXIS_NAMES[a]} error ({AXIS_UNITS[a]})", fontsize=8)
        for ax in axs[-1]:
            ax.set_xlabel("frame time (s)", fontsize=8)

    return draw


def draw_measured_series(report: dict, d: dict) -> Callable[[Figure, Rect], None]:
    """Measured pose and reference over time: the steps and holds (Figs. 11-13)."""

    def draw(fig: Figure, rect: Rect) -> None:
        axs = axes_grid(fig, rect, 3, 2, "Measured pose and reference over time", sharex=True)
        for ax, a in zip(axs.T.ravel(), AXES, strict=True):
            ax.plot(d["t"], d["ref_" + a], "-", color="0.6", lw=1.0, label="reference")
            ax.plot(d["t"], d[a], ".", ms=2, label="measured")
            ax.set_ylabel(axis_label(a), fontsize=8)
        axs[0, 0].legend(loc="best", fontsize=7)
        for ax in axs[-1]:
            ax.set_xlabel("frame time (s)", fontsize=8)

    return draw


def draw_measured_vs_reference(report: dict) -> Callable[[Figure, Rect], None]:
    """Mean measured value per set-point against the reference (Fig. 14)."""

    def draw(fig: Figure, rect: Rect) -> None:
        sps = report["setpoints"]
        axs = axes_grid(fig, rect, 2, 3, "Measured (mean per set-point) vs reference", gap_y_in=0.6)
        for ax, a in zip(axs.ravel(), AXES, strict=True):
            ref_v = np.array([_num(sp["reference"][a]) for sp in sps])
            mean = ref_v + np.array([_num(sp["axes"][a]["bias"]) for sp in sps])
            ax.plot(ref_v, mean, "o", ms=4)
            lo, hi = np.nanmin(np.r_[ref_v, mean, 0.0]), np.nanmax(np.r_[ref_v, mean, 0.0])
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            ax.xaxis.set_major_locator(_max_n_locator(4))
            ax.set_xlabel(f"reference {axis_label(a)}", fontsize=8)
            ax.set_ylabel(f"measured ({AXIS_UNITS[a]})", fontsize=8)

    return draw


def draw_error_vs_range(report: dict) -> Callable[[Figure, Rect], None]:
    """Mean error +/- 1 std per set-point against range, translation and attitude; against
    the set-point number when every set-point is at about the same range."""

    def draw(fig: Figure, rect: Rect) -> None:
        sps = report["setpoints"]
        x, xlabel = range_or_index(sps)
        what = "range" if xlabel.startswith("range") else "set-point"
        axs = axes_grid(fig, rect, 1, 2, f"Error vs {what} (mean per set-point, +/- 1 std)")[0]
        for ax, group, unit in ((axs[0], AXES[:3], "mm"), (axs[1], AXES[3:], "deg")):
            for a in group:
                bias = np.array([_num(sp["axes"][a]["bias"]) for sp in sps])
                std = np.array([_num(sp["axes"][a]["std"]) for sp in sps])
                ax.errorbar(
                    x, bias, yerr=np.nan_to_num(std), fmt="o", ms=4, capsize=2, label=AXIS_NAMES[a]
                )
            ax.set_xlabel(xlabel, fontsize=8)
            ax.xaxis.set_major_locator(_max_n_locator(6, integer=what == "set-point"))
            ax.set_ylabel(f"mean error +/- 1 std ({unit})", fontsize=8)
            ax.legend(fontsize=7)

    return draw


def range_or_index(setpoints: list[dict]) -> tuple[np.ndarray, str]:
    """(x values, label): the reference range in m, or the set-point number when the
    ranges span less than 1 % of their mean."""
    range_m = np.array([_num(sp["reference"]["z_mm"]) for sp in setpoints]) / 1000.0
    finite = range_m[np.isfinite(range_m)]
    if finite.size and np.ptp(finite) > 0.01 * abs(float(np.mean(finite))):
        return range_m, "range (reference z, m)"
    return np.array([sp["setpoint_index"] for sp in setpoints], float), "set-point"


def share_plot(report: dict) -> Plot:
    """The verdict's bar chart (beside the verdict table in the PDF)."""
    return Plot(
        "max |error| as a share of the requirement", draw_requirement_share(report), 1.6, 2.4
    )


def evidence_plots(report: dict, rows: list[dict]) -> list[Plot]:
    """The plots after the tables: time series, measured vs reference, error vs range;
    none when no frame gave a pose (``NO_PLOTS`` says so instead)."""
    if not report["n_ok"]:
        return []
    d = frame_arrays(rows, report["reference"])
    return [
        Plot("Error per frame (time series)", draw_error_series(report, d), 4.0, 7.3),
        Plot("Measured and reference over time", draw_measured_series(report, d), 4.0, 7.3),
        Plot("Measured vs reference per set-point", draw_measured_vs_reference(report), 4.0, 7.3),
        Plot("Error vs range", draw_error_vs_range(report), 2.6, 4.2),
    ]


def standalone(plot: Plot, width_in: float = 10.0, height_in: float | None = None) -> Figure:
    """The plot alone in a figure (the HTML report's images)."""
    h = height_in if height_in is not None else min(plot.max_height_in, 1.25 * plot.min_height_in)
    from matplotlib.figure import Figure  # on the first report (docs/server.md, "Memory")

    fig = Figure(figsize=(width_in, h))  # no pyplot: freed with its last reference
    plot.draw(fig, (0.0, 0.0, width_in, h))
    return fig
