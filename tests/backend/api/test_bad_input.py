"""Bad input gets a 4xx naming what is wrong, never a 500, and changes nothing."""

from __future__ import annotations

import pytest

from tests.backend.conftest import AUTH

JSON = {**AUTH, "Content-Type": "application/json"}


def _detail_text(r) -> str:
    d = r.json()["detail"]
    return d if isinstance(d, str) else " ".join(f"{e['loc']} {e['msg']}" for e in d)


@pytest.mark.parametrize(
    ("path", "method", "raw", "needle"),
    [
        ("/api/motion/move", "post", b'{"yaw_deg": 1', "json"),
        ("/api/motion/move", "post", b"yaw_deg=1", "json"),
        ("/api/motion/move", "post", b'{"yaw_deg": "ten"}', "yaw_deg"),
        ("/api/motion/move", "post", b'{"yaw_deg": NaN}', "yaw_deg"),
        ("/api/motion/move", "post", b'{"yaw_deg": 1e999}', "yaw_deg"),
        ("/api/motion/move", "post", b'{"azimuth_deg": 3}', "azimuth_deg"),
        ("/api/motion/move", "post", b"[1, 2, 3]", "body"),
        ("/api/camera/settings", "put", b'{"frame_rate_hz": 0}', "frame_rate_hz"),
        ("/api/camera/settings", "put", b'{"modulation_frequency_mhz": 1000}', "modulation"),
        ("/api/camera/settings", "put", b'{"exposure": 3}', "exposure"),
        ("/api/catalogs", "post", b'{"name": "a", "reflectors": [1, 2, 3]}', "reflectors"),
        ("/api/catalogs", "post", b'{"name": "../etc", "reflectors": []}', "name"),
        # Strict types: no coercion of booleans or strings into numbers and back.
        ("/api/motion/move", "post", b'{"yaw_deg": true}', "yaw_deg"),
        ("/api/motion/move", "post", b'{"yaw_deg": "5"}', "yaw_deg"),
        ("/api/camera/settings", "put", b'{"auto_exposure": "yes"}', "auto_exposure"),
        ("/api/camera/settings", "put", b'{"auto_exposure": 1}', "auto_exposure"),
        ("/api/camera/settings", "put", b'{"frame_rate_hz": "10"}', "frame_rate_hz"),
        (
            "/api/catalogs",
            "post",
            b'{"name": "s", "reflectors": [{"id": "1", "position_mm": [0, 0, 0], '
            b'"diameter_mm": 1}]}',
            "id",
        ),
    ],
)
def test_malformed_bodies_are_422_with_a_message(client, path, method, raw, needle):
    r = client.request(method, path, content=raw, headers=JSON)
    assert r.status_code == 422, r.text
    assert needle.lower() in _detail_text(r).lower()


def test_unusable_catalog_geometry_is_422_and_nothing_is_stored(client):
    before = client.get("/api/catalogs").json()
    collinear = {
        "name": "line",
        "reflectors": [
            {"id": i, "position_mm": [100.0 * i, 0, 0], "diameter_mm": 40} for i in range(4)
        ],
    }
    r = client.post("/api/catalogs", json=collinear, headers=AUTH)
    assert r.status_code == 422 and "collinear" in _detail_text(r)
    dup = {**collinear, "name": "dup"}
    dup["reflectors"] = [
        {**x, "id": 1, "position_mm": [x["position_mm"][0], x["id"] * 50.0, 0]}
        for x in collinear["reflectors"]
    ]
    r = client.post("/api/catalogs", json=dup, headers=AUTH)
    assert r.status_code == 422 and "duplicate" in _detail_text(r)
    assert client.get("/api/catalogs").json() == before


def test_bad_settings_leave_the_settings_unchanged(client):
    before = client.get("/api/camera/settings").json()
    r = client.put(
        "/api/camera/settings", json={"frame_rate_hz": 15, "auto_exposure": "maybe"}, headers=AUTH
    )
    assert r.status_code == 422
    assert client.get("/api/camera/settings").json() == before


def test_huge_bodies_are_refused_with_413(client):
    big = (
        b'{"name": "x", "reflectors": ['
        + b'{"id": 1, "position_mm": [0,0,0], "diameter_mm": 1},' * 40000
        + b"]}"
    )  # noqa: E501
    assert len(big) > 1_000_000
    r = client.post("/api/catalogs", content=big, headers=JSON)
    assert r.status_code == 413 and "limit" in r.json()["detail"]

    def chunks():  # no Content-Length: the limit applies while streaming
        for _ in range(200):
            yield b" " * 10_000

    r = client.post("/api/motion/move", content=chunks(), headers=JSON)
    assert r.status_code == 413


def test_unknown_resources_and_bad_queries_are_4xx(client):
    assert client.get("/api/catalogs/nope").status_code == 404
    assert client.post("/api/catalogs/nope/activate", headers=AUTH).status_code == 404
    assert client.get("/api/frames/latest/depth.png").status_code == 422
    assert client.get("/api/frames/latest/gray.png?scale=9").status_code == 422
    assert client.get("/api/pose/history?n=0").status_code == 422
    assert client.get("/api/nothing").status_code == 404


def test_integers_are_still_numbers(client):
    """Strictness does not refuse a JSON integer where a number is expected."""
    r = client.post("/api/motion/move", json={"yaw_deg": 1}, headers=AUTH)
    assert r.status_code == 202, r.text


def test_soft_limit_errors_print_the_value_with_its_digits(client):
    r = client.post("/api/motion/move", json={"yaw_deg": -170.0001}, headers=AUTH)
    assert r.status_code == 422
    text = _detail_text(r)
    assert "-170.0001 deg" in text and "[-170, 170]" in text


@pytest.mark.parametrize(
    ("authorization", "status"),
    [
        (None, 401),
        ("Bearer wrong-token", 401),
        ("Basic dGVzdDp0ZXN0", 401),
        ("Bearer", 401),
        ("bearer test-token-0123456789", 202),  # scheme names are case-insensitive
        ("Bearer test-token-0123456789", 202),
    ],
)
def test_authorization_header_variants(client, authorization, status):
    headers = {"Authorization": authorization} if authorization else {}
    r = client.post("/api/motion/move", json={"yaw_deg": 0.5}, headers=headers)
    assert r.status_code == status, r.text
    if status == 401:
        assert r.headers["www-authenticate"] == "Bearer"
