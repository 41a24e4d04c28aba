"""The API docs pages work offline: every asset they name is served by us."""

from __future__ import annotations

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
