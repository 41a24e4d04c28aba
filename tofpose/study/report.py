"""A study's ``summary.json``, and its report: ``report.html`` (plots in ``plots/``) and
``report.pdf`` (the same plots and the table), from the summary alone.

Plots: attitude error (p50 solid, p95 dashed) against range, a line per attitude spread,
a panel per remaining condition (offset, ambient, physics, catalog, preset); success %
as a map of condition x range, wrong poses marked; NEES / 6 and the share of poses
beyond 3 sigma against range. Figures are made with matplotlib's object API (no pyplot
state), so that a server thread can write a report.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from tofpose.study.spec import StudySpec

PLOTS = ("attitude_vs_range.png", "success_map.png", "consistency_vs_range.png")


def write_summary(root: str | Path, summary: dict) -> Path:
    path = Path(root) / "summary.json"
    path.write_text(json.dumps(summary, indent=2, sort_keys=True))
    return path


def _condition(cell: dict) -> str:
    return (
        f"off {cell['offset_fraction']:g}, {cell['ambient_lux']:g} lx, {cell['physics']}, "
        f"{cell['catalog']}, {cell['preset']}"
    )


def _row_label(cell: dict) -> str:
    return f"+-{cell['attitude_deg']:g} deg, {_condition(cell)}"


def _nan(x) -> float:
    return math.nan if x is None else float(x)


def _figures(summary: dict) -> list[Figure]:
    cells = summary["cells"]
    ranges = sorted({c["range_m"] for c in cells})
    conditions = sorted({_condition(c) for c in cells})
    attitudes = sorted({c["attitude_deg"] for c in cells})
    by = {(_condition(c), c["attitude_deg"], c["range_m"]): c for c in cells}

    n = len(conditions)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig1 = Figure(figsize=(5.0 * cols, 3.6 * rows))
    axes = fig1.subplots(rows, cols, squeeze=False).ravel()
    for ax, cond in zip(axes, conditions, strict=False):
        for k, att in enumerate(attitudes):
            cs = [by.get((cond, att, r)) for r in ranges]
            p50 = [_nan(c["attitude_error_deg"]["p50"]) if c else math.nan for c in cs]
            p95 = [_nan(c["attitude_error_deg"]["p95"]) if c else math.nan for c in cs]
            colour = f"C{k}"
            ax.plot(ranges, p50, "o-", color=colour, label=f"+-{att:g} deg p50")
            ax.plot(ranges, p95, "s--", color=colour, label=f"+-{att:g} deg p95")
        ax.set_title(cond, fontsize=9)
        ax.set_xlabel("range (m)")
        ax.set_ylabel("attitude error (deg)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig1.suptitle("Attitude error of the reported poses against range")

    labels = sorted({_row_label(c) for c in cells})
    cell_at = {(_row_label(c), c["range_m"]): c for c in cells}
    grid = np.full((len(labels), len(ranges)), np.nan)
    fig2 = Figure(
        figsize=(2.0 + 1.1 * len(ranges) + 0.06 * max(map(len, labels)), 1.5 + 0.45 * len(labels))
    )
    ax = fig2.subplots()
    for i, lab in enumerate(labels):
        for j, r in enumerate(ranges):
            c = cell_at.get((lab, r))
            if c is not None and c["success_pct"] is not None:
                grid[i, j] = c["success_pct"]
    im = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=100, aspect="auto")
    for i, lab in enumerate(labels):
        for j, r in enumerate(ranges):
            c = cell_at.get((lab, r))
            if c is None:
                continue
            text = "-" if c["success_pct"] is None else f"{c['success_pct']:.0f}%"
            if c["wrong"]:
                text += f"\n{c['wrong']} wrong"
            ax.text(j, i, text, ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(ranges)), [f"{r:g} m" for r in ranges])
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    fig2.colorbar(im, ax=ax, label="success %")
    ax.set_title("Success % per cell (wrong poses noted)", fontsize=10)

    fig3 = Figure(figsize=(11, 3.8))
    a1, a2 = fig3.subplots(1, 2)
    for k, lab in enumerate(labels):
        cs = [cell_at.get((lab, r)) for r in ranges]
        a1.plot(
            ranges,
            [_nan(c["nees_over_6"]) if c else math.nan for c in cs],
            "o-",
            color=f"C{k % 10}",
            label=lab,
        )
        a2.plot(
            ranges,
            [_nan(c["beyond_3sigma_pct"]) if c else math.nan for c in cs],
            "o-",
            color=f"C{k % 10}",
            label=lab,
        )
    a1.axhline(1.0, color="k", lw=0.8, ls=":")
    a1.set_ylabel("mean NEES / 6 (1 = consistent)")
    a2.axhline(0.27, color="k", lw=0.8, ls=":")
    a2.set_ylabel("poses beyond 3 sigma (%)")
    for a in (a1, a2):
        a.set_xlabel("range (m)")
        a.grid(alpha=0.3)
    a2.legend(fontsize=7)
    fig3.suptitle("Does the reported covariance hold?")
    for f in (fig1, fig2, fig3):
        f.tight_layout()
    return [fig1, fig2, fig3]


TABLE_HEAD = (
    "cell",
    "frames",
    "success %",
    "wrong",
    "conf. wrong",
    "no pose",
    "> 3 sigma %",
    "NEES/6",
    "att p50/p95/p99 deg",
    "pos p50/p95/p99 mm",
    "main failure",
)


def table_rows(summary: dict) -> list[tuple[str, ...]]:
    """One row per cell of the report's table (``TABLE_HEAD``)."""

    def f(x, digits=1):
        return "-" if x is None else f"{x:.{digits}f}"

    out: list[tuple[str, ...]] = []
    for c in summary["cells"]:
        a, p = c["attitude_error_deg"], c["position_error_mm"]
        fails = c["failures"]
        main = max(fails, key=fails.get) + f" ({fails[max(fails, key=fails.get)]})" if fails else ""
        out.append(
            (
                c["label"],
                str(c["frames"]),
                f(c["success_pct"]),
                str(c["wrong"]),
                str(c["confidently_wrong"]),
                str(c["no_pose"]),
                f(c["beyond_3sigma_pct"]),
                f(c["nees_over_6"], 2),
                "/".join(f(a[k], 3) for k in ("p50", "p95", "p99")),
                "/".join(f(p[k], 1) for k in ("p50", "p95", "p99")),
                main,
            )
        )
    return out


def write_report(root: str | Path, spec: StudySpec, summary: dict, run: dict | None = None) -> Path:
    """report.html, report.pdf and plots/*.png from ``summary``; returns the HTML's path."""
    root = Path(root)
    plots = root / "plots"
    plots.mkdir(exist_ok=True)
    figures = _figures(summary)
    for fig, name in zip(figures, PLOTS, strict=True):
        fig.savefig(plots / name, dpi=100)
    rows = table_rows(summary)
    with PdfPages(root / "report.pdf") as pdf:
        for fig in figures:
            pdf.savefig(fig)
        per_page = 28
        for k in range(0, len(rows), per_page):
            fig = Figure(figsize=(16, 9))
            ax = fig.subplots()
            ax.axis("off")
            tab = ax.table(
                cellText=rows[k : k + per_page], colLabels=TABLE_HEAD, loc="upper center"
            )
            tab.auto_set_font_size(False)
            tab.set_fontsize(6)
            tab.auto_set_column_width(range(len(TABLE_HEAD)))
            ax.set_title(f"Study {spec.name!r}: cells {k + 1}-{min(k + per_page, len(rows))}")
            pdf.savefig(fig)
    esc = html.escape
    run_text = ""
    if run:
        fps = run.get("frames_per_s")
        n = run["workers"]
        run_text = (
            f"<p>Run: {run['frames_run']} frames on {esc(str(run['cluster']))} "
            f"({n} worker{'s' if n != 1 else ''}) in {run['wall_s']:.1f} s, of which "
            f"{run.get('cluster_start_s', 0.0):.1f} s starting the cluster"
            + (f"; {fps:.1f} frames/s after that" if fps else "")
            + ".</p>"
        )
    total = summary["all"] or {}
    body = "\n".join("<tr>" + "".join(f"<td>{esc(x)}</td>" for x in r) + "</tr>" for r in rows)
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Study {esc(spec.name)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1400px}}
table{{border-collapse:collapse;font-size:13px}}td,th{{border:1px solid #ccc;padding:3px 6px}}
th{{background:#eee}}img{{max-width:100%;margin:1em 0}}</style></head><body>
<h1>Accuracy study {esc(spec.name)}</h1>
<p>{spec.n_cells} cells x {spec.frames_per_cell} frames (seed {spec.seed});
{summary["frames_stored"]} of {summary["frames_planned"]} frames
stored{"" if summary["complete"] else " <strong>(incomplete)</strong>"}.
All frames: success {total.get("success_pct") or 0:.1f} %, {total.get("wrong", 0)} wrong,
{total.get("confidently_wrong", 0)} confidently wrong.</p>
{run_text}
<p>Rules: success is a pose within 1 deg and max(20 mm, 0.5 % of the range); wrong is a
pose beyond 2 deg or 2.5 times that; confidently wrong is wrong and beyond 3 reported sigmas
(chi-square(6) at 0.9973). Percentiles are over every reported pose.</p>
{"".join(f'<img src="plots/{p}" alt="{p}">' for p in PLOTS)}
<table><tr>{"".join(f"<th>{esc(h)}</th>" for h in TABLE_HEAD)}</tr>
{body}
</table>
<p>Per-frame results: <code>frames/*.parquet</code>; statistics: <code>summary.json</code>;
spec: <code>study.json</code>.</p>
</body></html>
"""
    path = root / "report.html"
    path.write_text(page)
    return path
