"""Rendering a report keeps nothing alive (docs/server.md, "Memory"): its matplotlib
figures are freed when the report is made, also when drawing one of them fails, and the
server does not import matplotlib (nor pyarrow, nor Dask) until a route needs it."""

from __future__ import annotations

import gc
import subprocess
import sys
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.services.reports import reports as reports_module
from backend.services.reports.report_plots import Plot
from backend.services.reports.reports import build, to_html, to_pdf
from tests.backend.services.reports.test_reports import BAD_OFFSETS, REQ, _store

ROOT = Path(__file__).resolve().parents[4]


def _live_figures() -> int:
    gc.collect()
    return sum(isinstance(o, Figure) for o in gc.get_objects())


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    engine = make_engine(f"sqlite:///{tmp_path_factory.mktemp('mem') / 'r.db'}")
    upgrade_database(engine)
    sessions = make_session_factory(engine)
    cid = _store(sessions, "bad", BAD_OFFSETS, REQ, 2)
    with sessions() as s:
        yield build(s, cid)
    engine.dispose()


def test_pdf_and_html_reports_leave_no_figure_alive(report):
    rep, rows = report
    before = _live_figures()
    pdf, html = to_pdf(rep, rows), to_html(rep, rows)
    assert pdf.startswith(b"%PDF") and html.count("data:image/png;base64,") >= 3
    assert _live_figures() == before


def test_a_plot_that_fails_to_draw_leaves_no_figure_alive(report, monkeypatch):
    rep, rows = report

    def boom(fig, rect):
        fig.add_axes((0.1, 0.1, 0.8, 0.8)).plot([0, 1], [0, 1])
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(reports_module, "evidence_plots", lambda *_: [Plot("boom", boom, 2.0, 3.0)])
    before = _live_figures()
    with pytest.raises(RuntimeError, match="drawing failed"):
        to_html(rep, rows)
    # with pyplot the half-drawn figure stayed in its global registry until closed
    assert _live_figures() == before


def test_the_server_imports_no_plotting_columnar_or_cluster_library_until_used():
    code = (
        "import sys, backend.app\n"
        "print(' '.join(m for m in ('matplotlib', 'pyarrow', 'dask', 'distributed')"
        " if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert out.stdout.strip() == "", f"imported with the server: {out.stdout.strip()}"
