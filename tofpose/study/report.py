"""A study's ``summary.json``, and its report: ``report.html`` (plots in ``plots/``) and
``report.pdf``, from the summary alone, in the order a campaign report reads: the
verdict first (the study in one paragraph, then a row per cell: PASS / FAIL against the
spec's requirements with the number that decides it and the main failure mode,
``tofpose.study.verdict``), then the statistics, then the plots.

The PDF's pages are all A4 landscape (the campaign report's size), text at 10 pt and
tables at 9 pt; a table longer than a page continues on the next with its header
repeated. Cells are labelled by the grid axes that vary; the fixed ones are said once.

Plots: attitude error (p50 solid, p95 dashed) against range, a line per attitude spread,
a panel per remaining condition; the share of frames within every requirement as a map
of condition x range, each cell marked PASS / FAIL; NEES / 6 and the share of poses
beyond 3 sigma against range. Figures are made with matplotlib's object API (no pyplot
state), so that a server thread can write a report.
"""

from __future__ import annotations

import html
import json
import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from tofpose.study.spec import StudyRequirements, StudySpec
from tofpose.study.verdict import rule_text

PLOTS = ("attitude_vs_range.png", "success_map.png", "consistency_vs_range.png")

PAGE_IN = (11.69, 8.27)  # A4 landscape, as the campaign report
MARGIN_X_IN, MARGIN_TOP_IN, MARGIN_BOTTOM_IN = 0.5, 0.45, 0.55
TEXT_PT = 10.0
TABLE_PT = 9.0
TITLE_PT = 16.0
LINE_SPACING = 1.3
PT_PER_IN = 72.0
CHAR_EM = 0.55  # mean character width of DejaVu Sans, in em
PASS_COLOUR, FAIL_COLOUR, NOTE_COLOUR = "#1a7f37", "#c62828", "#444444"
#: the cell's axes, in the order a label names them
CONDITION_AXES = (
    "range_m",
    "attitude_deg",
    "offset_fraction",
    "ambient_lux",
    "physics",
    "catalog",
    "preset",
)


def write_summary(root: str | Path, summary: dict) -> Path:
    path = Path(root) / "summary.json"
    path.write_text(json.dumps(summary, indent=2, sort_keys=True))
    return path


# -- labels ----------------------------------------------------------------------------------
def _axis_text(axis: str, value) -> str:
    return {
        "range_m": lambda v: f"{v:g} m",
        "attitude_deg": lambda v: f"+-{v:g} deg",
        "offset_fraction": lambda v: f"off {v:g}",
        "ambient_lux": lambda v: f"{v:g} lx",
    }.get(axis, str)(value)


def varying_axes(cells: list[dict]) -> list[str]:
    """The grid axes with more than one value among ``cells``."""
    return [a for a in CONDITION_AXES if len({c[a] for c in cells}) > 1]


def short_label(cell: dict, varying: list[str]) -> str:
    """The cell by the axes that vary (all of them when none does)."""
    axes = varying or list(CONDITION_AXES)
    return ", ".join(_axis_text(a, cell[a]) for a in axes)


def fixed_text(cells: list[dict]) -> str:
    """``Every cell: off 0.5, 1000 lx, paper-target, default.``: the axes that do not vary."""
    vary = varying_axes(cells)
    if not cells or not vary:
        return ""
    fixed = [a for a in CONDITION_AXES if a not in vary]
    return "Every cell: " + ", ".join(_axis_text(a, cells[0][a]) for a in fixed) + "."


def _condition(cell: dict) -> str:
    return (
        f"off {cell['offset_fraction']:g}, {cell['ambient_lux']:g} lx, {cell['physics']}, "
        f"{cell['catalog']}, {cell['preset']}"
    )


def _row_label(cell: dict) -> str:
    return f"+-{cell['attitude_deg']:g} deg, {_condition(cell)}"


def _nan(x) -> float:
    return math.nan if x is None else float(x)


def _f(x, digits: int = 1) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


# -- tables ----------------------------------------------------------------------------------
@dataclass
class TextTable:
    """Text cells with a header; ``status[(row, column)]``: True pass, False fail."""

    header: list[str]
    rows: list[list[str]]
    caption: str = ""
    status: dict[tuple[int, int], bool] = field(default_factory=dict)


VERDICT_HEAD = ["cell", "condition", "verdict", "the number that decides", "within all %"]
VERDICT_HEAD += ["main failure mode"]
STATS_HEAD = [
    "cell",
    "condition",
    "frames",
    "poses",
    "no pose",
    "gross success %",
    "wrong",
    "conf. wrong",
    "> 3 sigma %",
    "NEES/6",
    "att p50/p95/p99 deg",
    "pos p50/p95/p99 mm",
]


def verdict_table(summary: dict) -> TextTable:
    """A row per cell: PASS / FAIL, the deciding number, the share of frames within
    every requirement, the main failure mode (``tofpose.study.verdict``)."""
    cells = summary["cells"]
    vary = varying_axes(cells)
    rows, status = [], {}
    for r, c in enumerate(cells):
        v = c["verdict"]
        verdict = {True: "PASS", False: "FAIL", None: "-"}[v["passed"]]
        rows.append(
            [
                str(c["cell"]),
                short_label(c, vary),
                verdict,
                v["number"],
                _f(v["within_all_pct"]),
                v["main_failure"] or "-",
            ]
        )
        if v["passed"] is not None:
            status[(r, 2)] = bool(v["passed"])
    return TextTable(VERDICT_HEAD, rows, "Verdict per cell", status)


def statistics_table(summary: dict) -> TextTable:
    """A row per cell: frames, poses, the gross rules of ``tofpose.lab.pose_judgement``,
    the covariance's consistency and the error percentiles."""
    cells = summary["cells"]
    vary = varying_axes(cells)
    rows = []
    for c in cells:
        a, p = c["attitude_error_deg"], c["position_error_mm"]
        rows.append(
            [
                str(c["cell"]),
                short_label(c, vary),
                str(c["frames"]),
                str(c["poses"]),
                str(c["no_pose"]),
                _f(c["success_pct"]),
                str(c["wrong"]),
                str(c["confidently_wrong"]),
                _f(c["beyond_3sigma_pct"]),
                _f(c["nees_over_6"], 2),
                "/".join(_f(a[k], 3) for k in ("p50", "p95", "p99")),
                "/".join(_f(p[k], 1) for k in ("p50", "p95", "p99")),
            ]
        )
    return TextTable(STATS_HEAD, rows, "Statistics per cell")


def table_rows(summary: dict) -> list[tuple[str, ...]]:
    """The verdict table's rows (``VERDICT_HEAD``)."""
    return [tuple(r) for r in verdict_table(summary).rows]


# -- the study in words ----------------------------------------------------------------------
def title(spec: StudySpec) -> str:
    return f"Accuracy study {spec.name}"


def size_text(spec: StudySpec, summary: dict) -> str:
    done = "" if summary["complete"] else " (incomplete: the verdict covers what is stored)"
    return (
        f"{spec.n_cells} cells x {spec.frames_per_cell} frames (seed {spec.seed}); "
        f"{summary['frames_stored']} of {summary['frames_planned']} frames stored{done}."
    )


def run_text(run: dict | None) -> str:
    if not run:
        return ""
    fps = run.get("frames_per_s")
    n = run["workers"]
    return (
        f"Run: {run['frames_run']} frames on {run['cluster']} "
        f"({n} worker{'s' if n != 1 else ''}) in {run['wall_s']:.1f} s, of which "
        f"{run.get('cluster_start_s', 0.0):.1f} s starting the cluster"
        + (f"; {fps:.1f} frames/s after that" if fps else "")
        + "."
    )


GROSS_RULES = (
    "Gross rules (tofpose.lab.pose_judgement, the bench's): gross success is a pose within "
    "1 deg and max(20 mm, 0.5 % of the range); wrong is a pose beyond 2 deg or 2.5 times "
    "that; confidently wrong is wrong and beyond 3 reported sigmas (chi-square(6) at 0.9973). "
    "Percentiles are over every reported pose; att is the geodesic attitude error, pos the "
    "position error's length."
)
FAILURE_NOTE = (
    "Failure modes: a frame without a pose is named by the pipeline's reason for refusing it "
    "(without its numbers), or 'no pose and no recorded reason' when the reason is empty; a "
    "pose outside the requirements by the axis it misses by the largest share."
)


def _requirements(spec: StudySpec, summary: dict) -> StudyRequirements:
    doc = summary.get("requirements")
    return StudyRequirements.from_dict(doc) if doc is not None else spec.requirements


def _verdict_colour(summary: dict) -> str:
    return {True: PASS_COLOUR, False: FAIL_COLOUR}.get(summary["verdict"]["passed"], "#222222")


# -- plots -----------------------------------------------------------------------------------
def _chunks(items: list, n: int) -> list[list]:
    return [items[k : k + n] for k in range(0, len(items), n)] or [[]]


def attitude_figures(summary: dict) -> list[Figure]:
    """Attitude error p50 / p95 against range: a panel per condition, at most 6 a page."""
    cells = summary["cells"]
    ranges = sorted({c["range_m"] for c in cells})
    attitudes = sorted({c["attitude_deg"] for c in cells})
    by = {(_condition(c), c["attitude_deg"], c["range_m"]): c for c in cells}
    figures = []
    for conditions in _chunks(sorted({_condition(c) for c in cells}), 6):
        n = len(conditions)
        cols = min(n, 3)
        rows = math.ceil(n / cols)
        fig = Figure(figsize=PAGE_IN)
        axes = fig.subplots(rows, cols, squeeze=False).ravel()
        for ax, cond in zip(axes, conditions, strict=False):
            for k, att in enumerate(attitudes):
                cs = [by.get((cond, att, r)) for r in ranges]
                p50 = [_nan(c["attitude_error_deg"]["p50"]) if c else math.nan for c in cs]
                p95 = [_nan(c["attitude_error_deg"]["p95"]) if c else math.nan for c in cs]
                colour = f"C{k % 10}"
                ax.plot(ranges, p50, "o-", color=colour, label=f"+-{att:g} deg p50")
                ax.plot(ranges, p95, "s--", color=colour, label=f"+-{att:g} deg p95")
            ax.set_title(cond, fontsize=10)
            ax.set_xlabel("range (m)")
            ax.set_ylabel("attitude error (deg)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=9)
        for ax in axes[n:]:
            ax.set_visible(False)
        fig.suptitle("Attitude error (geodesic) of the reported poses against range")
        fig.tight_layout(rect=(0.02, 0.05, 0.98, 0.97))
        figures.append(fig)
    return figures


def verdict_map_figures(summary: dict) -> list[Figure]:
    """Frames within every requirement (%) per cell, condition x range, each cell marked
    PASS / FAIL; at most 14 conditions and 10 ranges a page."""
    cells = summary["cells"]
    cell_at = {(_row_label(c), c["range_m"]): c for c in cells}
    figures = []
    pages = [
        (labels, ranges)
        for labels in _chunks(sorted({_row_label(c) for c in cells}), 14)
        for ranges in _chunks(sorted({c["range_m"] for c in cells}), 10)
    ]
    for labels, ranges in pages:
        grid = np.full((len(labels), len(ranges)), np.nan)
        fig = Figure(figsize=PAGE_IN)
        ax = fig.subplots()
        for i, lab in enumerate(labels):
            for j, r in enumerate(ranges):
                c = cell_at.get((lab, r))
                if c is not None and c["verdict"]["within_all_pct"] is not None:
                    grid[i, j] = c["verdict"]["within_all_pct"]
        im = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=100, aspect="auto")
        for i, lab in enumerate(labels):
            for j, r in enumerate(ranges):
                c = cell_at.get((lab, r))
                if c is None:
                    continue
                v = c["verdict"]
                word = {True: "PASS", False: "FAIL", None: "-"}[v["passed"]]
                pct = "-" if v["within_all_pct"] is None else f"{v['within_all_pct']:.0f} %"
                # the colour map's ends are dark: white text there
                dark = v["within_all_pct"] is not None and not 25.0 <= v["within_all_pct"] <= 85.0
                ax.text(
                    j,
                    i,
                    f"{word}\n{pct}",
                    ha="center",
                    va="center",
                    fontsize=9,
                    weight="bold",
                    color="white" if dark else "black",
                )
        ax.set_xticks(range(len(ranges)), [f"{r:g} m" for r in ranges])
        ax.set_yticks(range(len(labels)), labels, fontsize=9)
        fig.colorbar(im, ax=ax, label="frames within every requirement (%)")
        ax.set_title("Verdict per cell: frames within every requirement (%)", fontsize=11)
        fig.tight_layout(rect=(0.02, 0.05, 0.98, 0.97))
        figures.append(fig)
    return figures


def consistency_figure(summary: dict) -> Figure:
    """NEES / 6 and the share of poses beyond 3 sigma against range, a line per
    condition."""
    cells = summary["cells"]
    ranges = sorted({c["range_m"] for c in cells})
    labels = sorted({_row_label(c) for c in cells})
    cell_at = {(_row_label(c), c["range_m"]): c for c in cells}
    fig = Figure(figsize=PAGE_IN)
    a1, a2 = fig.subplots(1, 2)
    for k, lab in enumerate(labels):
        cs = [cell_at.get((lab, r)) for r in ranges]
        for a, key in ((a1, "nees_over_6"), (a2, "beyond_3sigma_pct")):
            a.plot(
                ranges,
                [_nan(c[key]) if c else math.nan for c in cs],
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
    if len(labels) <= 12:
        a2.legend(fontsize=9)
    fig.suptitle("Does the reported covariance hold?")
    fig.tight_layout(rect=(0.02, 0.05, 0.98, 0.97))
    return fig


def _figures(summary: dict) -> list[list[Figure]]:
    """The figures of each plot in ``PLOTS`` (a plot may take several pages)."""
    return [attitude_figures(summary), verdict_map_figures(summary), [consistency_figure(summary)]]


# -- PDF pages -------------------------------------------------------------------------------
def _chars(width_in: float, size_pt: float) -> int:
    return max(8, int(width_in * PT_PER_IN / (CHAR_EM * size_pt)))


class _Pages:
    """Text and tables flowed down A4 landscape pages (``PAGE_IN``), top to bottom."""

    def __init__(self, pdf: PdfPages, footer: str):
        self.pdf = pdf
        self.footer = footer
        self.width_in = PAGE_IN[0] - 2 * MARGIN_X_IN
        self.figures: list[Figure] = []
        self.fig: Figure | None = None
        self.y_in = 0.0  # from the page's top

    def _new(self) -> Figure:
        self.fig = Figure(figsize=PAGE_IN)
        self.figures.append(self.fig)
        self.y_in = MARGIN_TOP_IN
        return self.fig

    def _room(self) -> float:
        return PAGE_IN[1] - MARGIN_BOTTOM_IN - self.y_in

    def text(self, paragraphs: list[str], size_pt=TEXT_PT, weight="normal", colour="#222222"):
        lines = []
        for p in (p for p in paragraphs if p):
            lines += textwrap.wrap(p, _chars(self.width_in, size_pt)) or [""]
        line_in = size_pt * LINE_SPACING / PT_PER_IN
        for line in lines:
            if self.fig is None or self._room() < line_in:
                self._new()
            assert self.fig is not None
            self.fig.text(
                MARGIN_X_IN / PAGE_IN[0],
                1 - self.y_in / PAGE_IN[1],
                line,
                fontsize=size_pt,
                weight=weight,
                color=colour,
                va="top",
            )
            self.y_in += line_in
        self.y_in += 0.1

    def _widths(self, table: TextTable) -> list[int]:
        """Each column's width in characters: its longest cell, the widest columns
        shrunk (their cells wrapped) until the table fits the page."""
        total = _chars(self.width_in, TABLE_PT) - 2 * len(table.header)
        want = [
            max([len(r[c]) for r in table.rows] + [min(len(table.header[c]), 12)])
            for c in range(len(table.header))
        ]
        while sum(want) > total:
            k = int(np.argmax(want))
            want[k] -= 1
        return want

    def table(self, table: TextTable):
        widths = self._widths(table)
        unit_in = self.width_in / sum(w + 2 for w in widths)
        col_in = [(w + 2) * unit_in for w in widths]
        lefts = [MARGIN_X_IN + sum(col_in[:k]) for k in range(len(col_in))]
        line_in = TABLE_PT * 1.25 / PT_PER_IN
        pairs = zip(table.header, widths, strict=True)
        head = [textwrap.wrap(h, max(w, 6)) or [""] for h, w in pairs]
        head_in = max(map(len, head)) * line_in + 0.08
        cells = [
            [textwrap.wrap(v, w) or [""] for v, w in zip(row, widths, strict=True)]
            for row in table.rows
        ]

        def start_page(caption: str):
            if self.fig is None or self._room() < head_in + 0.8 + 3 * line_in:
                self._new()
            assert self.fig is not None
            if caption:
                self.text([caption], TABLE_PT + 2, "bold")
            assert self.fig is not None
            self._rect(MARGIN_X_IN, self.y_in, self.width_in, head_in, "#e6e6e6")
            for c, lines in enumerate(head):
                self._put(lefts[c] + 0.05, self.y_in + 0.04, "\n".join(lines), "bold")
            self.y_in += head_in

        start_page(table.caption)
        for r, lines in enumerate(cells):
            h = max(map(len, lines)) * line_in + 0.06
            if self._room() < h:
                self._new()
                start_page(f"{table.caption} (continued)")
            if r % 2:
                self._rect(MARGIN_X_IN, self.y_in, self.width_in, h, "#f3f3f3")
            for c, cell in enumerate(lines):
                state = table.status.get((r, c))
                colour = "#222222" if state is None else PASS_COLOUR if state else FAIL_COLOUR
                self._put(
                    lefts[c] + 0.05,
                    self.y_in + 0.03,
                    "\n".join(cell),
                    "bold" if state is not None else "normal",
                    colour,
                )
            self.y_in += h
        self.y_in += 0.15

    def _rect(self, x_in, top_in, w_in, h_in, colour):
        assert self.fig is not None
        self.fig.patches.append(
            Rectangle(
                (x_in / PAGE_IN[0], 1 - (top_in + h_in) / PAGE_IN[1]),
                w_in / PAGE_IN[0],
                h_in / PAGE_IN[1],
                transform=self.fig.transFigure,
                color=colour,
                lw=0,
                zorder=-1,
            )
        )

    def _put(self, x_in, top_in, text, weight="normal", colour="#222222"):
        assert self.fig is not None
        self.fig.text(
            x_in / PAGE_IN[0],
            1 - top_in / PAGE_IN[1],
            text,
            fontsize=TABLE_PT,
            weight=weight,
            color=colour,
            va="top",
            linespacing=1.1,
        )

    def figure(self, fig: Figure):
        self.fig = None  # what follows starts a new page
        self.figures.append(fig)

    def close(self):
        n = len(self.figures)
        for k, fig in enumerate(self.figures, start=1):
            fig.text(
                0.5,
                0.25 / PAGE_IN[1],
                f"{self.footer} - page {k} of {n}",
                ha="center",
                fontsize=8,
                color="#666666",
            )
            self.pdf.savefig(fig)


def write_pdf(path: Path, spec: StudySpec, summary: dict, figures: list[Figure], run: dict | None):
    """report.pdf: the verdict, the statistics, the plots; every page A4 landscape."""
    req = _requirements(spec, summary)
    with PdfPages(path) as pdf:
        pages = _Pages(pdf, f"{title(spec)} - tofpose study report")
        pages.text([title(spec)], TITLE_PT, "bold")
        pages.text([summary["verdict"]["text"]], TEXT_PT + 1, "bold", _verdict_colour(summary))
        pages.text([size_text(spec, summary), run_text(run), fixed_text(summary["cells"])])
        pages.text([rule_text(req), FAILURE_NOTE], TEXT_PT - 1, colour=NOTE_COLOUR)
        pages.table(verdict_table(summary))
        pages.table(statistics_table(summary))
        pages.text([GROSS_RULES], TEXT_PT - 1, colour=NOTE_COLOUR)
        for fig in figures:
            pages.figure(fig)
        pages.close()


# -- HTML ------------------------------------------------------------------------------------
def _html_table(table: TextTable) -> str:
    esc = html.escape
    head = "".join(f"<th>{esc(h)}</th>" for h in table.header)
    body = []
    for r, row in enumerate(table.rows):
        tds = []
        for c, v in enumerate(row):
            state = table.status.get((r, c))
            cls = "" if state is None else " class='pass'" if state else " class='fail'"
            tds.append(f"<td{cls}>{esc(v)}</td>")
        body.append("<tr>" + "".join(tds) + "</tr>")
    return (
        f"<table><caption>{esc(table.caption)}</caption><tr>{head}</tr>\n"
        + "\n".join(body)
        + "</table>"
    )


def write_report(root: str | Path, spec: StudySpec, summary: dict, run: dict | None = None) -> Path:
    """report.html, report.pdf and plots/*.png from ``summary``; returns the HTML's path."""
    root = Path(root)
    plots = root / "plots"
    plots.mkdir(exist_ok=True)
    per_plot = _figures(summary)
    for figs, name in zip(per_plot, PLOTS, strict=True):
        figs[0].savefig(plots / name, dpi=100)  # the HTML shows each plot's first page
    write_pdf(root / "report.pdf", spec, summary, [f for figs in per_plot for f in figs], run)
    esc = html.escape
    req = _requirements(spec, summary)
    colour = _verdict_colour(summary)
    paragraphs = [size_text(spec, summary), run_text(run), fixed_text(summary["cells"])]
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Study {esc(spec.name)}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1400px}}
table{{border-collapse:collapse;font-size:14px;margin:1em 0}}
td,th{{border:1px solid #ccc;padding:3px 6px}}
th{{background:#eee}}caption{{font-weight:bold;text-align:left;padding:4px 0}}
.pass{{color:{PASS_COLOUR};font-weight:bold}}.fail{{color:{FAIL_COLOUR};font-weight:bold}}
.verdict{{font-size:1.15em;font-weight:bold;color:{colour}}}.note{{color:{NOTE_COLOUR}}}
img{{max-width:100%;margin:1em 0}}</style></head><body>
<h1>{esc(title(spec))}</h1>
<p class="verdict" data-testid="study-verdict">{esc(summary["verdict"]["text"])}</p>
{"".join(f"<p>{esc(p)}</p>" for p in paragraphs if p)}
<p class="note">{esc(rule_text(req))} {esc(FAILURE_NOTE)}</p>
{_html_table(verdict_table(summary))}
{_html_table(statistics_table(summary))}
<p class="note">{esc(GROSS_RULES)}</p>
{"".join(f'<img src="plots/{p}" alt="{p}">' for p in PLOTS)}
<p>Per-frame results: <code>frames/*.parquet</code>; statistics: <code>summary.json</code>;
spec: <code>study.json</code>.</p>
</body></html>
"""
    path = root / "report.html"
    path.write_text(page)
    return path
