"""The API docs pages work offline: every asset they name is served by us."""

from __future__ import annotations

import html
import re

import pytest


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_load_only_assets_from_this_server(client, page):
    r = client.get(page)
    assert r.status_code == 200
    urls = re.findall(r'(?:src|href)="([^"]+)"', r.text)
    urls += re.findall(r"url: '([^']+)'", r.text) + re.findall(r'spec-url="([^"]+)"', r.text)
    assert urls, "no assets found in the page"
    for url in urls:
        assert url.startswith("/") and not url.startswith("//"), f"{page} loads {url}"
        assert client.get(url).status_code == 200, url
    assert "cdn." not in r.text and "fonts.googleapis" not in r.text


def test_root_serves_the_built_dashboard_or_says_how_to_build_it(tmp_path):
    from tests.backend.conftest import make_settings, running_app

    dist = tmp_path / "dist"
    dist.mkdir()
    (dist / "index.html").write_text("<!doctype html><title>dash</title>")
    with running_app(make_settings(tmp_path / "a", frontend_dir=dist)) as c:
        r = c.get("/")
        assert r.status_code == 200 and "<title>dash</title>" in r.text
        assert c.get("/api/health").status_code == 200  # API routes win over the mount
    with running_app(make_settings(tmp_path / "b", frontend_dir=tmp_path / "none")) as c:
        r = c.get("/", follow_redirects=False)
        assert r.status_code == 503 and r.headers["content-type"].startswith("text/html")
        page = html.unescape(r.text)
        assert "dashboard is not built" in page and str(tmp_path / "none") in page
        assert "make frontend" in page and "cd frontend && npm ci && npm run build" in page
        assert 'href="/docs"' in r.text and r.headers["cache-control"] == "no-store"
        assert c.get("/docs").status_code == 200 and c.get("/api/health").status_code == 200
