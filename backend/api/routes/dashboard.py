"""The dashboard at ``/`` (frontend/, a Vite build): its page, and its hashed assets under
``/assets``. Not a catch-all mount at ``/``: that would answer 404 instead of 405 for a
wrong method on an API path.

Where the build is looked for is ``Settings.frontend_dist`` (the wheel's copy, the
checkout's ``frontend/dist`` or ``TOFPOSE_FRONTEND_DIR``). When it is not there, ``/``
answers a small page saying so, how to build it, and where the API docs are, with 503:
the server runs, but a part of it that a browser, a smoke test (``curl -f``) or a health
check asks for at ``/`` is not available, and a success status would hide a broken
install. Neither route is in the API document.

``install`` also adds the hardening headers (``backend.security_headers``: no framing,
``nosniff``, no referrer) to every answer of the server, the API's included: the
dashboard is the page a hostile site would frame, and its API is what that page calls.
"""

from __future__ import annotations

import html
import logging
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from starlette.staticfiles import StaticFiles

from backend.security_headers import SecurityHeaders

log = logging.getLogger("tofpose.server")

BUILD_COMMANDS = ("make frontend", "cd frontend && npm ci && npm run build")

NOT_BUILT_PAGE = """<!doctype html>
<html lang="en">
<head><meta charset="utf-8"><title>tofpose: dashboard not built</title></head>
<body>
<h1>The dashboard is not built</h1>
<p>This server found no built dashboard (no <code>index.html</code> in
<code>{dist}</code>). The API runs: its documentation is at <a href="/docs">/docs</a>.</p>
<p>To build the dashboard in a source checkout, run <code>{make}</code> (or
<code>{npm}</code>), then restart the server. Or point <code>TOFPOSE_FRONTEND_DIR</code>
at a built copy. A wheel (<code>pip install .</code>) carries the dashboard.</p>
</body>
</html>
"""


def is_built(dist: Path) -> bool:
    """Whether ``dist`` holds a built dashboard (its page)."""
    return (dist / "index.html").is_file()


def not_built_page(dist: Path) -> str:
    """The HTML page ``/`` answers when there is no dashboard in ``dist``."""
    make, npm = BUILD_COMMANDS
    return NOT_BUILT_PAGE.format(dist=html.escape(str(dist)), make=make, npm=html.escape(npm))


def _serve_built(app: FastAPI, dist: Path) -> None:
    """``/`` -> ``index.html`` (revalidated: it names the current hashed assets)."""
    app.mount(
        "/assets", StaticFiles(directory=dist / "assets", check_dir=False), name="dashboard-assets"
    )

    @app.get("/", include_in_schema=False)
    def dashboard() -> FileResponse:
        return FileResponse(dist / "index.html", headers={"Cache-Control": "no-cache"})


def _serve_not_built(app: FastAPI, dist: Path) -> None:
    """``/`` -> the not-built page, 503, not cached (build the dashboard, then restart
    the server)."""
    log.warning(
        "dashboard not built (no index.html in %s): / says how to build it (%s)",
        dist,
        BUILD_COMMANDS[0],
    )
    page = not_built_page(dist)

    @app.get("/", include_in_schema=False)
    def dashboard_not_built() -> HTMLResponse:
        return HTMLResponse(page, status_code=503, headers={"Cache-Control": "no-store"})


def install(app: FastAPI, dist: Path) -> None:
    """Serve the dashboard built in ``dist`` at ``/``, or the page saying it is not, and
    add the hardening headers to every answer of ``app`` (installed outermost when
    called after the app's other middleware, as ``create_app`` does: the Host check's
    400 and the body limit's 413 carry them too)."""
    app.add_middleware(SecurityHeaders)
    if is_built(dist):
        _serve_built(app, dist)
    else:
        _serve_not_built(app, dist)
