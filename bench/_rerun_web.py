"""Rerun's web viewer in headless chromium: a screenshot of what it shows on some files
(``bench/viewers.py``, ``bench/interop.py``; Debian's chromium, software WebGL)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench._common import free_port
from bench.live import CHROMIUM, CHROMIUM_ARGS


def rerun_web_screenshot(
    files: list[Path], out_png: Path, viewport: tuple[int, int], load_s: float
) -> None:
    """``rerun --serve-web FILES`` on free ports, opened in chromium at ``viewport``
    (width, height px); after ``load_s`` seconds (the wasm viewer loads, then streams the
    files) the page is written to ``out_png``; the viewer is stopped either way."""
    from playwright.sync_api import sync_playwright

    web, grpc = free_port(), free_port()
    rerun = Path(sys.executable).parent / "rerun"
    # its own session: ``rerun`` is a wrapper that starts the viewer binary as a child,
    # and both must go when we are done
    proc = subprocess.Popen(
        [str(rerun), "--serve-web", *map(str, files)]
        + ["--web-viewer-port", str(web), "--port", str(grpc)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        time.sleep(5.0)
        args = [a for a in CHROMIUM_ARGS if a != "--disable-gpu"] + ["--ignore-gpu-blocklist"]
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=args)
            width, height = viewport
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"http://127.0.0.1:{web}/?url=rerun%2Bhttp://127.0.0.1:{grpc}/proxy")
            time.sleep(load_s)
            out_png.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(out_png))
            browser.close()
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(10)
