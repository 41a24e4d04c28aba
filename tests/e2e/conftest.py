"""Browser tests: Debian's chromium driven by Playwright (no browser download), against a
live server that serves the built dashboard. Every request to another host fails the
test (a lab may be offline)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest

CHROMIUM = "/usr/bin/chromium"
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    # WebGL for the 3-D scene without a GPU: SwiftShader, software rendering
    "--use-gl=swiftshader",
    "--enable-unsafe-swiftshader",
]
SHOTS = Path(__file__).resolve().parents[2] / "out" / "screenshots"  # gitignored


@pytest.fixture(scope="session", autouse=True)
def screenshot_dir() -> Path:
    SHOTS.mkdir(parents=True, exist_ok=True)
    return SHOTS


@pytest.fixture(scope="session")
def browser():
    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} missing: `make test` installs Debian's chromium")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


@pytest.fixture
def page_for(browser) -> Iterator:
    """page_for(base_url, token=None) -> a page that refuses off-host requests."""
    pages, foreign = [], []

    def make(base_url: str, token: str | None = None):
        ctx = browser.new_context(viewport={"width": 1366, "height": 768})
        if token:
            ctx.add_init_script(f"sessionStorage.setItem('tofpose-token', {token!r})")
        host = urlsplit(base_url).hostname

        def guard(route):
            url = urlsplit(route.request.url)
            if url.scheme in ("http", "https", "ws", "wss") and url.hostname != host:
                foreign.append(route.request.url)
                route.abort()
            else:
                route.continue_()

        ctx.route("**/*", guard)
        page = ctx.new_page()
        pages.append(ctx)
        return page

    yield make
    for ctx in pages:
        ctx.close()
    assert not foreign, f"the dashboard requested other hosts: {foreign[:5]}"


def live_page_with_matches(page_for, base_url: str, token: str):
    """The dashboard at ``base_url``, opened with ``token``, once its live view has drawn
    a frame with matched reflectors labelled on the overlay (60 s at most each)."""
    page = page_for(base_url, token)
    page.goto(base_url + "/")
    page.get_by_test_id("frame-index").wait_for(timeout=60_000)
    page.wait_for_function(
        "(document.querySelector('[data-testid=overlay]').dataset.labels || '').length > 0",
        timeout=60_000,
    )
    return page
