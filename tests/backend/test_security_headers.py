"""Every answer of the main server carries the hardening headers: the dashboard's page and
assets, the API, its errors (404, the Host check's 400, a body too large) and the
not-built page; the report the dashboard frames itself may be framed by its own origin
only."""

from __future__ import annotations

import pytest

from backend.security_headers import HEADERS, SAME_ORIGIN_FRAME_HEADERS
from tests.backend.conftest import AUTH, make_settings, running_app

NO_FRAMING = {
    "content-security-policy": "frame-ancestors 'none'",
    "x-frame-options": "DENY",
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
}


def hardening(response) -> dict[str, str]:
    return {name: response.headers.get(name) for name in NO_FRAMING}


@pytest.fixture(scope="module")
def built_app(tmp_path_factory):
    dist = tmp_path_factory.mktemp("dist")
    (dist / "index.html").write_text("<!doctype html><title>tofpose</title>")
    (dist / "assets").mkdir()
    (dist / "assets" / "index-abc123.js").write_text("console.log('dashboard')")
    settings = make_settings(tmp_path_factory.mktemp("data"), frontend_dir=dist)
    with running_app(settings) as client:
        yield client


def test_the_headers_are_the_ones_the_module_promises():
    assert {k.lower(): v for k, v in HEADERS.items()} == NO_FRAMING


@pytest.mark.parametrize(
    ("path", "status"),
    [
        ("/", 200),  # the dashboard
        ("/assets/index-abc123.js", 200),  # its assets (a mounted static app)
        ("/api/health", 200),
        ("/api/no-such-thing", 404),
        ("/assets/missing.js", 404),
        ("/openapi.json", 200),
        ("/docs", 200),
    ],
)
def test_every_answer_forbids_framing_sniffing_and_referrers(built_app, path, status):
    r = built_app.get(path)
    assert r.status_code == status
    assert hardening(r) == NO_FRAMING


def test_refusals_before_any_route_carry_them_too(built_app):
    foreign_host = built_app.get("/api/health", headers={"Host": "evil.example"})
    assert foreign_host.status_code == 400
    assert hardening(foreign_host) == NO_FRAMING
    too_large = built_app.post(
        "/api/catalogs",
        content=b"x" * 2_000_000,
        headers={**AUTH, "Content-Type": "application/json"},
    )
    assert too_large.status_code == 413
    assert hardening(too_large) == NO_FRAMING
    no_token = built_app.post("/api/motion/stop")
    assert no_token.status_code == 401
    assert hardening(no_token) == NO_FRAMING


def test_the_report_may_be_framed_by_the_dashboards_own_origin_only(built_app):
    r = built_app.get("/api/campaigns/987654/report.html", params={"inline": "true"})
    assert r.status_code == 404  # no such campaign: the headers go by the path
    assert hardening(r) == {k.lower(): v for k, v in SAME_ORIGIN_FRAME_HEADERS.items()}
    assert r.headers["content-security-policy"] == "frame-ancestors 'self'"
    assert r.headers["x-frame-options"] == "SAMEORIGIN"
    # a path that merely starts like it is not the report
    assert hardening(built_app.get("/api/campaigns/987654/report.html/x")) == NO_FRAMING


def test_the_not_built_page_carries_them(tmp_path):
    settings = make_settings(tmp_path / "data", frontend_dir=tmp_path / "no-dist")
    with running_app(settings) as client:
        r = client.get("/")
    assert r.status_code == 503
    assert hardening(r) == NO_FRAMING


def test_a_routes_own_header_is_kept_and_the_policy_is_added_beside_its_own():
    from starlette.applications import Starlette
    from starlette.responses import PlainTextResponse
    from starlette.routing import Route
    from starlette.testclient import TestClient

    from backend.security_headers import SecurityHeaders

    def own(_request):
        headers = {
            "Referrer-Policy": "same-origin",
            "Content-Security-Policy": "default-src 'self'",
        }
        return PlainTextResponse("x", headers=headers)

    app = Starlette(routes=[Route("/own", own)])
    app.add_middleware(SecurityHeaders)
    r = TestClient(app).get("/own")
    assert r.headers["referrer-policy"] == "same-origin"
    assert r.headers.get_list("content-security-policy") == [
        "default-src 'self'",
        "frame-ancestors 'none'",
    ]
    assert r.headers["x-frame-options"] == "DENY"
