"""The study report on constructed frames with known errors: the PDF's pages all have one
size (A4 landscape, the campaign report's), its first page starts with the title and
the study's verdict, then the verdict per cell before the statistics; every failing cell
names its failure; the HTML reads in the same order."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from tests.tofpose.study.study_rows import frame_row, table
from tofpose.study.report import PAGE_IN, TABLE_PT, write_report
from tofpose.study.spec import StudySpec
from tofpose.study.summary import summarise

N = 20
A4_LANDSCAPE_PT = (841.68, 595.44)  # 297 x 210 mm
LIGATURES = {"ff", "fi", "fl", "ffi", "ffl"}


def _rows(cells: int) -> list[dict]:
    """Cell 0 passes (pitch 0.1 deg); cell 1 fails on pitch (0.2 deg); cell 2 has no pose
    in 4 frames with an empty reason; the rest pass; every cell N frames."""
    rows = []
    for c in range(cells):
        for i in range(N):
            if c == 2 and i < 4:
                rows.append(frame_row(c, i, ok=False, reason=""))
            else:
                rows.append(frame_row(c, i, pitch_deg=0.2 if c == 1 else 0.1))
    return rows


def _pdf(tmp_path: Path, ranges: list[float]) -> tuple[Path, dict]:
    spec = StudySpec.from_dict(
        {
            "name": "known",
            "frames_per_cell": N,
            "grid": {"range_m": ranges, "physics": ["ideal", "all"]},
        }
    )
    summary = summarise(spec, table(_rows(spec.n_cells)))
    write_report(tmp_path, spec, summary)
    return tmp_path / "report.pdf", summary


def _page_sizes(pdf: Path) -> list[tuple[float, float]]:
    info = subprocess.run(
        ["pdfinfo", "-f", "1", "-l", "999", str(pdf)], check=True, capture_output=True, text=True
    ).stdout
    return [
        (float(w), float(h)) for w, h in re.findall(r"Page +\d+ size: +([\d.]+) x ([\d.]+)", info)
    ]


def _text(pdf: Path, *options: str) -> str:
    out = subprocess.run(
        ["pdftotext", *options, str(pdf), "-"], check=True, capture_output=True, text=True
    )
    return " ".join(out.stdout.split())


@pytest.mark.parametrize("n_ranges", [2, 30])  # 4 cells, and 60 (tables over several pages)
def test_every_page_is_a4_landscape_and_the_report_starts_with_the_verdict(tmp_path, n_ranges):
    pdf, summary = _pdf(tmp_path, [1.0 + 0.5 * k for k in range(n_ranges)])
    sizes = _page_sizes(pdf)
    assert len(sizes) >= 4 + (n_ranges > 2)  # the tables, then three plots
    assert set(sizes) == {A4_LANDSCAPE_PT}, sizes
    assert pytest.approx((11.69, 8.27)) == PAGE_IN and TABLE_PT >= 9
    first = _text(pdf, "-f", "1", "-l", "1")
    verdict = summary["verdict"]["text"]
    assert verdict.startswith(f"FAIL: {2 * n_ranges - 2} of {2 * n_ranges} cells meet")
    assert first.startswith("Accuracy study known " + verdict[:60])
    whole = _text(pdf)
    assert whole.index("Verdict per cell") < whole.index("Statistics per cell")


def test_every_failing_cell_names_its_failure(tmp_path):
    pdf, summary = _pdf(tmp_path, [3.0, 5.0])
    by_cell = {c["cell"]: c["verdict"] for c in summary["cells"]}
    assert by_cell[1]["main_failure"] == f"pitch beyond 0.15 deg ({N} of {N} frames)"
    assert by_cell[2]["main_failure"] == f"no pose and no recorded reason (4 of {N} frames)"
    raw = _text(pdf, "-raw")
    for words in (
        "FAIL pitch p95 |error| 0.2 deg = 133 % of 0.15 deg",
        "FAIL no pose in 4 of 20 frames (20.0 %)",
        "no pose and no recorded reason (4 of 20 frames)",
    ):
        assert words in raw, words
    page = (tmp_path / "report.html").read_text()
    assert (
        page.index("study-verdict")
        < page.index("Verdict per cell")
        < page.index("Statistics per cell")
    )
    assert page.count("class='fail'") == 2 and page.count("class='pass'") == 2


def _word_heights(pdf: Path, page: int) -> list[tuple[float, float, str]]:
    """(top, height, word) of every word on ``page`` (pdftotext -bbox, pt)."""
    out = subprocess.run(
        ["pdftotext", "-bbox", "-f", str(page), "-l", str(page), str(pdf), "-"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    words = re.findall(r'yMin="([\d.]+)" xMax="[\d.]+" yMax="([\d.]+)">([^<]*)</word>', out)
    return [(float(a), float(b) - float(a), w) for a, b, w in words]


def test_no_text_but_the_footer_is_smaller_than_9_pt(tmp_path):
    pdf, _ = _pdf(tmp_path, [1.0 + 0.5 * k for k in range(30)])
    n_table_pages = sum(1 for _ in _page_sizes(pdf)) - 5  # the last are plots
    for page in range(1, n_table_pages + 1):
        words = _word_heights(pdf, page)
        footer_top = A4_LANDSCAPE_PT[1] - 0.5 * 72  # the footer's line, 8 pt
        footer = [h for top, h, _ in words if top > footer_top]
        # a ligature glyph ("off" is drawn o + ff) has a box of its own, shorter than
        # its line's: not a word
        body = [h for top, h, w in words if top <= footer_top and w not in LIGATURES]
        assert footer and body
        pt_per_height = 8.0 / max(footer)  # the word boxes' height per point of font size
        smallest = min(body) * pt_per_height
        assert smallest >= 9.0 - 0.05, (page, smallest)
