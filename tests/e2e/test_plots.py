"""The live plots in a real browser at 1366 x 768: the pose and every plot on the first
screen, legends in words with units, the error against the named (uncalibrated)
reference, the time window, pause while the stream goes on, zoom, and the CSV of exactly
what is shown."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest

from backend.services.live.live_reference import NOMINAL_LABEL
from tests.backend.conftest import TOKEN, LiveServer, make_settings
from tests.e2e.conftest import SHOTS

CHARTS = ["xy", "z", "attitude", "error-position", "error-attitude", "rate"]
TIME_COLUMNS = ["capture time (UTC)", "capture time (Unix s)", "frame", "frame time (s)"]


@pytest.fixture
def server(tmp_path):
    with LiveServer(make_settings(tmp_path / "data")) as srv:
        yield srv


def _csv(page) -> tuple[list[str], list[dict[str, str]]]:
    with page.expect_download() as download:
        page.get_by_test_id("plot-csv").click()
    text = Path(download.value.path()).read_text()
    rows = list(csv.reader(io.StringIO(text)))
    header = rows[0]
    return header, [dict(zip(header, r, strict=True)) for r in rows[1:]]


def _span_s(rows: list[dict[str, str]]) -> float:
    times = [float(r["capture time (Unix s)"]) for r in rows]
    assert times == sorted(times)
    return times[-1] - times[0]


def _frame(page) -> int:
    return int(page.get_by_test_id("frame-index").inner_text().removeprefix("frame "))


def test_plots_window_pause_zoom_and_csv_at_1366x768(server, page_for):
    page = page_for(server.base_url, TOKEN)
    page.goto(server.base_url + "/")
    page.get_by_test_id("pose-x").wait_for(timeout=30_000)
    page.get_by_test_id("frame-index").wait_for(timeout=20_000)

    page.wait_for_timeout(1000)  # a few frames in the plots
    page.screenshot(path="/tmp/plots-first-screen.png")

    # the pose and every plot, legend included, on the first screen
    assert page.evaluate("window.innerWidth") == 1366
    assert page.evaluate("window.innerHeight") == 768
    assert page.evaluate("window.scrollY") == 0
    boxes = {"pose": page.get_by_test_id("pose").bounding_box()}
    boxes |= {c: page.get_by_test_id(f"chart-{c}").bounding_box() for c in CHARTS}
    for name, b in boxes.items():
        assert b is not None and b["width"] > 100 and b["height"] > 60, (name, b)
        assert b["x"] >= 0 and b["y"] >= 0, (name, b)
        assert b["x"] + b["width"] <= 1366 and b["y"] + b["height"] <= 768, (name, b)

    # legends in words with units; the error plot names its reference as uncalibrated
    legends = page.locator(".u-legend").all_inner_texts()
    text = " ".join(legends)
    for label in ("x (mm)", "pitch (deg)", "reference yaw (deg)", "error z (mm)", "rate y (deg/s)"):
        assert label in text, (label, text)
    assert "_mm" not in text and "_deg" not in text
    page.wait_for_function(
        "document.querySelector('[data-testid=chart-error-position-title]').innerText"
        f".includes({NOMINAL_LABEL!r})",
        timeout=10_000,
    )
    assert "uncalibrated" in page.get_by_test_id("chart-error-attitude-title").inner_text()

    # the 10 s window once more than 10 s of frames have come
    page.wait_for_timeout(12_000)
    page.get_by_test_id("plot-window-10").click()
    assert page.get_by_test_id("plot-window-10").get_attribute("aria-pressed") == "true"
    assert page.get_by_test_id("plot-window-30").get_attribute("aria-pressed") == "false"
    page.screenshot(path=str(SHOTS / "dashboard-plots.png"))
    page.screenshot(path="/tmp/plots-live.png")

    # pause: what is shown and exported stays while frames keep coming
    page.get_by_test_id("plot-pause").click()
    header, rows = _csv(page)
    assert header[:4] == TIME_COLUMNS
    for col in (
        "x (mm)",
        "z (mm)",
        "pitch (deg)",
        "reference x (mm)",
        "error x (mm)",
        "|error| (mm)",
    ):
        assert col in header, (col, header)
    assert 8.0 < _span_s(rows) <= 10.0
    assert len(rows) > 80  # 20 frames a second
    frames = [int(r["frame"]) for r in rows]
    assert frames == sorted(frames) and len(set(frames)) == len(frames)
    for r in rows[-5:]:
        x, ref, err = (float(r[c]) for c in ("x (mm)", "reference x (mm)", "error x (mm)"))
        assert err == pytest.approx(x - ref, abs=2e-6)
    status = page.get_by_test_id("plot-status").inner_text()
    assert "paused" in status
    frame_at_pause = _frame(page)
    page.wait_for_timeout(1500)
    assert _frame(page) > frame_at_pause + 10  # the stream went on
    assert page.get_by_test_id("plot-status").inner_text() == status
    assert _csv(page)[1] == rows  # the shown data did not move

    # a series hidden in its legend is not exported
    legend = page.get_by_test_id("chart-xy").locator(".u-legend .u-series")
    legend.filter(has_text="reference x (mm)").click()
    header2, rows2 = _csv(page)
    assert "reference x (mm)" not in header2 and "reference y (mm)" in header2
    assert len(rows2) == len(rows)

    # zoom: a drag over the middle third of a plot narrows every plot and the export
    over = page.get_by_test_id("chart-z").locator(".u-over").bounding_box()
    y = over["y"] + over["height"] / 2
    page.mouse.move(over["x"] + over["width"] * 0.33, y)
    page.mouse.down()
    page.mouse.move(over["x"] + over["width"] * 0.5, y, steps=5)
    page.mouse.move(over["x"] + over["width"] * 0.66, y, steps=5)
    page.mouse.up()
    assert "zoomed" in page.get_by_test_id("plot-status").inner_text()
    _, zoomed = _csv(page)
    assert 2.0 < _span_s(zoomed) < 4.5
    assert {r["frame"] for r in zoomed} < {r["frame"] for r in rows}
    page.screenshot(path="/tmp/plots-zoomed.png")
    # the wheel over a plot zooms out again (the CSV button took the mouse away)
    page.mouse.move(over["x"] + over["width"] * 0.5, y)
    for _ in range(3):
        page.mouse.wheel(0, 200)
        page.wait_for_timeout(100)
    _, wheeled = _csv(page)
    assert len(wheeled) > len(zoomed) + 20
    assert "zoomed" in page.get_by_test_id("plot-status").inner_text()
    page.get_by_test_id("plot-reset-zoom").click()
    assert "zoomed" not in page.get_by_test_id("plot-status").inner_text()
    assert _csv(page)[1] == rows2

    # resume: live again, newer frames shown
    page.get_by_test_id("plot-resume").click()
    page.wait_for_timeout(1000)
    assert "paused" not in page.get_by_test_id("plot-status").inner_text()
    _, later = _csv(page)
    assert int(later[-1]["frame"]) > int(rows[-1]["frame"]) + 10
    page.get_by_test_id("plot-window-120").click()
    _, longer = _csv(page)
    assert _span_s(longer) > 12.0
    page.screenshot(path="/tmp/plots-2min.png")
