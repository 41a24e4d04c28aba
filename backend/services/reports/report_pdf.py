"""The PDF campaign report: blocks (text, tables, plots, side-by-side rows) flowed onto
A4 landscape pages with matplotlib's PDF backend.

Blocks go down the page in order; a table that does not fit is split (its header
repeated), text is split by lines, a heading is never left alone at the foot of a page,
and the space a page has left is given to the plots on it (each up to its largest
height), so that pages are full rather than half blank.
"""

from __future__ import annotations

import io
import textwrap
from dataclasses import dataclass
from typing import TYPE_CHECKING

from backend.services.reports import report_content as rc
from backend.services.reports.report_camera import (
    camera_plots,
    camera_table,
    metadata_text,
)
from backend.services.reports.report_dynamic import dynamic_plots, dynamic_tables
from backend.services.reports.report_plots import (
    FAIL_COLOUR,
    NO_PLOTS,
    PASS_COLOUR,
    Plot,
    Rect,
    evidence_plots,
    share_plot,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PAGE_IN = (11.69, 8.27)  # A4 landscape
MARGIN_X_IN, MARGIN_TOP_IN, MARGIN_BOTTOM_IN = 0.5, 0.45, 0.5
CHAR_EM = 0.52  # mean character width of DejaVu Sans text, in em
CELL_CHAR_EM = 0.6  # of table cells (mostly digits, 0.64 em)
NOTE_COLOUR = "#444444"
MIN_SPLIT_ROWS = 3  # a table or text split over two pages keeps this many rows on each
LINE_SPACING = 1.35
PT_PER_IN = 72.0


def chars_per_line(width_in: float, fontsize_pt: float, em: float = CHAR_EM) -> int:
    """About how many characters of ``fontsize_pt`` fit in ``width_in``."""
    return max(10, int(width_in * PT_PER_IN / (em * fontsize_pt)))


def _frac(fig: Figure, rect: Rect) -> tuple[float, float, float, float]:
    fw, fh = fig.get_size_inches()
    x, y, w, h = rect
    return x / fw, y / fh, w / fw, h / fh


# -- blocks ----------------------------------------------------------------------------------
@dataclass
class Text:
    """Wrapped paragraphs (``bullets`` puts a dash before each)."""

    paragraphs: list[str]
    fontsize_pt: float = 9.0
    weight: str = "normal"
    bullets: bool = False
    space_after_in: float = 0.12
    keep_with_next: bool = False
    colour: str = "#222222"
    flexible = False

    def lines(self, width_in: float) -> list[str]:
        n = chars_per_line(width_in, self.fontsize_pt)
        out = []
        for p in self.paragraphs:
            first, rest = ("- ", "  ") if self.bullets else ("", "")
            out += textwrap.wrap(
                p, n, initial_indent=first, subsequent_indent=rest, break_on_hyphens=False
            ) or [""]
        return out

    def _line_in(self) -> float:
        return self.fontsize_pt * LINE_SPACING / PT_PER_IN

    def height_in(self, width_in: float) -> float:
        return len(self.lines(width_in)) * self._line_in() + self.space_after_in

    def split(self, height_in: float, width_in: float) -> tuple[Text, Text] | None:
        """The lines that fit in ``height_in`` and the rest, or None when that would leave
        fewer than ``MIN_SPLIT_ROWS`` lines on either side."""
        lines = self.lines(width_in)
        n = int((height_in - self.space_after_in) / self._line_in())
        if n < MIN_SPLIT_ROWS or len(lines) - n < MIN_SPLIT_ROWS:
            return None
        size, weight, colour = self.fontsize_pt, self.weight, self.colour
        return (
            Text(lines[:n], size, weight, space_after_in=0.0, colour=colour),
            Text(lines[n:], size, weight, colour=colour),
        )

    def draw(self, fig: Figure, rect: Rect) -> None:
        x, y, w, h = rect
        fw, fh = fig.get_size_inches()
        fig.text(
            x / fw,
            (y + h) / fh,
            "\n".join(self.lines(w)),
            fontsize=self.fontsize_pt,
            weight=self.weight,
            color=self.colour,
            va="top",
            ha="left",
            linespacing=LINE_SPACING,
        )


@dataclass
class TableBlock:
    """A table: a caption, a shaded header repeated on every page, pass/FAIL cells coloured."""

    table: rc.Table
    fontsize_pt: float = 7.5
    space_after_in: float = 0.12
    keep_with_next: bool = False
    flexible = False

    def _row_in(self) -> float:
        return self.fontsize_pt * 1.75 / PT_PER_IN

    def _caption_in(self) -> float:
        return (self.fontsize_pt + 1.5) * 1.45 / PT_PER_IN if self.table.caption else 0.0

    def header_lines(self, width_in: float) -> list[list[str]]:
        """Each column's header wrapped to about the width of its data."""
        cols = len(self.table.header)
        share = chars_per_line(width_in, self.fontsize_pt, CELL_CHAR_EM) // cols
        out = []
        for c, h in enumerate(self.table.header):
            data = max((len(r[c]) for r in self.table.rows), default=1)
            out.append(textwrap.wrap(h, max(data, share, 6), break_on_hyphens=False) or [""])
        return out

    def column_widths(self, width_in: float) -> list[float]:
        """Column widths (in) in proportion to their longest line, filling ``width_in``."""
        heads = self.header_lines(width_in)
        chars = [
            max([len(r[c]) for r in self.table.rows] + [len(s) for s in heads[c]]) + 2
            for c in range(len(heads))
        ]
        total = sum(chars)
        return [width_in * n / total for n in chars]

    def _header_in(self, width_in: float) -> float:
        n = max(len(h) for h in self.header_lines(width_in))
        return n * self.fontsize_pt * 1.15 / PT_PER_IN + 0.07

    def height_in(self, width_in: float) -> float:
        body = len(self.table.rows) * self._row_in()
        return self._caption_in() + self._header_in(width_in) + body + self.space_after_in

    def split(self, height_in: float, width_in: float):
        """The rows that fit and the rest (caption marked continued), or None when that
        would leave fewer than ``MIN_SPLIT_ROWS`` rows on either side."""
        fixed = self._caption_in() + self._header_in(width_in) + self.space_after_in
        n = int((height_in - fixed) / self._row_in())
        if n < MIN_SPLIT_ROWS or len(self.table.rows) - n < MIN_SPLIT_ROWS:
            return None
        cont = (self.table.caption + " (continued)") if self.table.caption else ""
        head = TableBlock(self.table.sliced(0, n), self.fontsize_pt, 0.0)
        tail = TableBlock(
            self.table.sliced(n, len(self.table.rows), cont), self.fontsize_pt, self.space_after_in
        )
        return head, tail

    def draw(self, fig: Figure, rect: Rect) -> None:
        x, y, w, h = rect
        ax = fig.add_axes(_frac(fig, rect))
        ax.set_axis_off()
        ax.set_xlim(0.0, w)
        ax.set_ylim(h, 0.0)  # inches from the top
        top = 0.0
        if self.table.caption:
            ax.text(
                0.0,
                top,
                self.table.caption,
                fontsize=self.fontsize_pt + 1.5,
                weight="bold",
                va="top",
            )
            top += self._caption_in()
        widths = self.column_widths(w)
        lefts = [sum(widths[:c]) for c in range(len(widths))]
        hh = self._header_in(w)
        from matplotlib.patches import Rectangle

        ax.add_patch(Rectangle((0.0, top), w, hh, color="#e6e6e6", lw=0))
        for c, lines in enumerate(self.header_lines(w)):
            ax.text(
                lefts[c] + widths[c] / 2,
                top + hh / 2,
                "\n".join(lines),
                ha="center",
                va="center",
                fontsize=self.fontsize_pt,
                weight="bold",
                linespacing=1.1,
            )
        top += hh
        self._draw_rows(ax, top, widths, lefts, w)

    def _draw_rows(self, ax, top: float, widths: list[float], lefts: list[float], w: float):
        from matplotlib.patches import Rectangle

        rh = self._row_in()
        for r, row in enumerate(self.table.rows):
            y0 = top + r * rh
            if r % 2:
                ax.add_patch(Rectangle((0.0, y0), w, rh, color="#f5f5f5", lw=0))
            for c, v in enumerate(row):
                state = self.table.status.get((r, c))
                colour = "#222222" if state is None else PASS_COLOUR if state else FAIL_COLOUR
                weight = "bold" if state is False else "normal"
                left = c == 0 or not _numeric(v)
                xt = lefts[c] + (0.05 if left else widths[c] - 0.05)
                ax.text(
                    xt,
                    y0 + rh / 2,
                    v,
                    ha="left" if left else "right",
                    va="center",
                    fontsize=self.fontsize_pt,
                    color=colour,
                    weight=weight,
                )
        bottom = top + len(self.table.rows) * rh
        ax.plot([0.0, w], [top, top], color="0.4", lw=0.6)
        ax.plot([0.0, w], [bottom, bottom], color="0.4", lw=0.6)


def _numeric(v: str) -> bool:
    head = v.split(" ")[0]
    try:
        float(head)
    except ValueError:
        return v == "-"
    return True


@dataclass
class PlotBlock:
    """A plot; it grows from its smallest to its largest height with the page's spare room."""

    plot: Plot
    space_after_in: float = 0.1
    keep_with_next: bool = False
    flexible = True

    def height_in(self, width_in: float) -> float:
        return self.plot.min_height_in + self.space_after_in

    def max_height_in(self) -> float:
        return self.plot.max_height_in + self.space_after_in

    def split(self, height_in: float, width_in: float):
        return None

    def draw(self, fig: Figure, rect: Rect) -> None:
        x, y, w, h = rect
        self.plot.draw(fig, (x, y + self.space_after_in, w, h - self.space_after_in))


@dataclass
class Row:
    """Blocks side by side (fractions of the width); a plot in it takes the row's height."""

    blocks: list[Block]
    fractions: list[float]
    gap_in: float = 0.3
    keep_with_next: bool = False
    flexible = False

    def _widths(self, width_in: float) -> list[float]:
        free = width_in - self.gap_in * (len(self.blocks) - 1)
        return [free * f for f in self.fractions]

    def height_in(self, width_in: float) -> float:
        return max(b.height_in(w) for b, w in zip(self.blocks, self._widths(width_in), strict=True))

    def split(self, height_in: float, width_in: float):
        return None

    def draw(self, fig: Figure, rect: Rect) -> None:
        x, y, w, h = rect
        for b, bw in zip(self.blocks, self._widths(w), strict=True):
            bh = h if b.flexible else b.height_in(bw)
            b.draw(fig, (x, y + h - bh, bw, bh))
            x += bw + self.gap_in


Block = Text | TableBlock | PlotBlock | Row
"""What goes down a page."""


# -- pagination ------------------------------------------------------------------------------
def heading(text: str, size_pt: float = 12.0) -> Text:
    return Text([text], size_pt, "bold", space_after_in=0.03, keep_with_next=True)


def paginate(
    blocks: list[Block], width_in: float, height_in: float
) -> list[list[tuple[Block, float]]]:
    """Pages of (block, height in): in order, splitting what does not fit, headings kept
    with what follows, a plot that does not fit swapped for a later one that does (like
    a float), each page's spare height shared out among its plots."""
    pages: list[list[list]] = [[]]
    used = 0.0
    queue = list(blocks)
    while queue:
        b = _next_fitting(queue, height_in - used, width_in) or _split_next(
            queue, height_in - used, width_in, page_empty=not pages[-1]
        )
        if b is None:
            pages.append([])
            used = 0.0
            continue
        h = b.height_in(width_in)
        pages[-1].append([b, h])
        used += h
    for page in pages:
        _stretch(page, height_in)
    return [[(b, h) for b, h in page] for page in pages if page]


def _next_fitting(queue: list, room_in: float, width_in: float):
    """Pop and return the next block if it fits in ``room_in`` (with the lead-in of what
    follows when it is a heading); else, when it is a plot, the first later plot that
    fits; else None (the queue unchanged)."""

    def fits(i: int) -> bool:
        b = queue[i]
        lead = _lead_in(queue[i + 1], width_in) if b.keep_with_next and i + 1 < len(queue) else 0
        return b.height_in(width_in) + lead <= room_in + 1e-9

    if fits(0):
        return queue.pop(0)
    if isinstance(queue[0], PlotBlock):
        for i in range(1, len(queue)):
            if isinstance(queue[i], PlotBlock) and fits(i):
                return queue.pop(i)
    return None


def _split_next(queue: list, room_in: float, width_in: float, page_empty: bool):
    """The part of the next block that fits in ``room_in`` (its rest stays queued); on an
    empty page the whole block when it cannot be split (larger than a page); else None."""
    b = queue[0]
    parts = None if b.keep_with_next else b.split(room_in, width_in)
    if parts:
        queue[0] = parts[1]
        return parts[0]
    return queue.pop(0) if page_empty else None


def _lead_in(b, width_in: float) -> float:
    """The least of ``b`` that must come onto the page with a heading before it: all of it
    unless it can be split, else its first ``MIN_SPLIT_ROWS`` rows or lines."""
    if isinstance(b, TableBlock) and len(b.table.rows) >= 2 * MIN_SPLIT_ROWS:
        return b._caption_in() + b._header_in(width_in) + MIN_SPLIT_ROWS * b._row_in()
    if isinstance(b, Text) and len(b.lines(width_in)) >= 2 * MIN_SPLIT_ROWS:
        return MIN_SPLIT_ROWS * b._line_in()
    return b.height_in(width_in)


def _stretch(page: list[list], height_in: float) -> None:
    """Give the page's spare height to its plots, equally, each up to its largest height."""
    spare = height_in - sum(h for _, h in page)
    flex = [item for item in page if item[0].flexible]
    while spare > 1e-6 and flex:
        each = spare / len(flex)
        for item in list(flex):
            grow = min(each, item[0].max_height_in() - item[1])
            item[1] += grow
            spare -= grow
            if item[0].max_height_in() - item[1] <= 1e-6:
                flex.remove(item)


# -- the report ------------------------------------------------------------------------------
def blocks(report: dict, rows: list[dict]) -> list[Block]:
    """The report's content in reading order: summary, verdict, findings, statistics,
    per-set-point table, plots."""
    note = "Full per-set-point statistics and the measured-value tables are in the HTML and JSON."
    verdict = Text(
        [rc.verdict_line(report)], 11.0, "bold", space_after_in=0.08, colour=_verdict_colour(report)
    )
    verdict_row = Row(
        [TableBlock(rc.verdict_table(report), 8.0), PlotBlock(share_plot(report), 0.0)], [0.6, 0.4]
    )
    out: list[Block] = [
        Text([rc.title(report)], 17.0, "bold", space_after_in=0.1),
        Text([rc.summary(report)], space_after_in=0.05),
        Text([metadata_text(report)]),
        heading("Verdict"),
        verdict,
        verdict_row,
        Text([rc.requirement_source(report)], 8.5),
        heading("Findings"),
        Text(rc.findings(report) or ["Nothing to add to the verdict."], bullets=True),
        heading("Accuracy over the whole campaign"),
        *(TableBlock(t) for t in rc.statistics_tables(report["overall"]["axes"])),
        Text([rc.reading_notes(report)], 8.0, colour=NOTE_COLOUR),
        heading("Per set-point"),
        TableBlock(rc.setpoint_table(report), 7.0),
        Text([note], 8.0, colour=NOTE_COLOUR),
    ]
    if report.get("camera_settings"):
        out += [
            heading("By camera setting"),
            TableBlock(camera_table(report), 7.5),
            *(PlotBlock(p) for p in camera_plots(report)),
        ]
    if report.get("dynamic"):
        out += [
            heading("Dynamic accuracy (motion profiles)"),
            *(TableBlock(t, 7.0) for t in dynamic_tables(report)),
            *(PlotBlock(p) for p in dynamic_plots(report)),
        ]
    plots: list[Block] = [PlotBlock(p) for p in evidence_plots(report, rows)]
    return out + (plots or [Text([NO_PLOTS])])


def _verdict_colour(report: dict) -> str:
    return {True: PASS_COLOUR, False: FAIL_COLOUR}.get(report["overall"]["passed"], "#222222")


def _footer(fig: Figure, report: dict, page: int, n_pages: int) -> None:
    fw, fh = fig.get_size_inches()
    generated = report["generated_at"][:19].replace("T", " ")
    text = (
        f"{rc.title(report)} - tofpose campaign report, generated {generated} UTC - "
        f"page {page} of {n_pages}"
    )
    fig.text(0.5, 0.22 / fh, text, ha="center", fontsize=7, color="#666666")


def to_pdf(report: dict, rows: list[dict]) -> bytes:
    """The report as PDF bytes, pages filled by ``paginate``."""
    width_in = PAGE_IN[0] - 2 * MARGIN_X_IN
    height_in = PAGE_IN[1] - MARGIN_TOP_IN - MARGIN_BOTTOM_IN
    pages = paginate(blocks(report, rows), width_in, height_in)
    # matplotlib is imported on the first report, not with the server (docs/server.md,
    # "Memory"); a Figure made without pyplot is in no global registry: it is freed when
    # the last reference goes, also when drawing raises
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    buf = io.BytesIO()
    with PdfPages(buf) as pdf:
        for k, page in enumerate(pages, start=1):
            fig = Figure(figsize=PAGE_IN)
            top = PAGE_IN[1] - MARGIN_TOP_IN
            for b, h in page:
                b.draw(fig, (MARGIN_X_IN, top - h, width_in, h))
                top -= h
            _footer(fig, report, k, len(pages))
            pdf.savefig(fig)
    return buf.getvalue()
