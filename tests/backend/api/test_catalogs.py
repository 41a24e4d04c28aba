"""POST /api/catalogs under concurrency: a unique-name race answers 409, never 500."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import httpx

import backend.api.routes.catalogs as catalogs_route
from tests.backend.conftest import AUTH

TRIANGLE = [
    {"id": 1, "position_mm": [0, 0, 0], "diameter_mm": 40},
    {"id": 2, "position_mm": [100, 0, 0], "diameter_mm": 40},
    {"id": 3, "position_mm": [0, 100, 0], "diameter_mm": 40},
]


def test_a_name_taken_between_the_check_and_the_insert_is_409(client, monkeypatch):
    """The route's look-up cannot see a row a concurrent request inserts after it: make
    the look-up blind and the database's unique constraint must still give 409."""
    body = {"name": "raced", "reflectors": TRIANGLE}
    assert client.post("/api/catalogs", json=body, headers=AUTH).status_code == 201
    monkeypatch.setattr(catalogs_route, "find_catalog", lambda *_: None)
    r = client.post("/api/catalogs", json=body, headers=AUTH)
    assert r.status_code == 409, r.text
    assert "'raced' already exists" in r.json()["detail"]


def test_concurrent_creates_of_one_name_give_one_201_and_409s(live_server):
    def post(i: int) -> int:
        body = {"name": f"race-{i // 10}", "reflectors": TRIANGLE}
        r = httpx.post(f"{live_server.base_url}/api/catalogs", json=body, headers=AUTH, timeout=30)
        return r.status_code

    with ThreadPoolExecutor(10) as pool:
        codes = list(pool.map(post, range(50)))  # 5 names, 10 requests each
    assert set(codes) <= {201, 409}, codes
    assert codes.count(201) == 5
    names = {c["name"] for c in httpx.get(f"{live_server.base_url}/api/catalogs").json()}
    assert {f"race-{k}" for k in range(5)} <= names
