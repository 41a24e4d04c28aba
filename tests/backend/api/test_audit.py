"""Scoped keys and the audit trail over HTTP: which scope each kind of request needs
(401 without a valid key, 403 naming the scope for one too low), the admin routes for
keys, every state-changing request recorded (refused ones too) with the key's name and a
redacted body, kept across a restart; and STOP answering while the worker threads are
all taken (every auth dependency is async)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import anyio

from tests.backend.conftest import AUTH, TOKEN, make_settings, running_app

TRIANGLE = [
    {"id": 1, "position_mm": [0, 0, 0], "diameter_mm": 40},
    {"id": 2, "position_mm": [100, 0, 0], "diameter_mm": 40},
    {"id": 3, "position_mm": [0, 100, 0], "diameter_mm": 40},
]


def _bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


def _make_key(client, name: str, scope: str) -> str:
    r = client.post("/api/keys", json={"name": name, "scope": scope}, headers=AUTH)
    assert r.status_code == 201, r.text
    assert r.headers["cache-control"] == "no-store"  # the key itself: no cache keeps it
    body = r.json()
    assert (body["name"], body["scope"], body["revoked_at"]) == (name, scope, None)
    return body["key"]


def _audit(client) -> list[dict]:
    client.app.state.tofpose.audit.flush()
    r = client.get("/api/audit", params={"limit": 1000}, headers=AUTH)
    assert r.status_code == 200, r.text
    return r.json()


def test_each_scope_gets_what_it_may_and_a_403_naming_the_scope_otherwise(client):
    read, operate = _make_key(client, "viewer", "read"), _make_key(client, "operator", "operate")
    stop = "/api/motion/stop"
    r = client.post(stop, headers=_bearer(read))
    assert r.status_code == 403
    assert r.json()["detail"] == "this request needs the 'operate' scope; key 'viewer' has 'read'"
    assert client.post(stop, headers=_bearer(operate)).status_code == 200
    assert client.post(stop, headers=AUTH).status_code == 200  # admin includes operate
    for key, name in ((read, "viewer"), (operate, "operator")):
        r = client.get("/api/audit", headers=_bearer(key))
        assert r.status_code == 403
        assert r.json()["detail"] == (
            f"this request needs the 'admin' scope; key {name!r} has "
            f"{'read' if key == read else 'operate'!r}"
        )
        assert (
            client.post(
                "/api/keys", json={"name": "x", "scope": "admin"}, headers=_bearer(key)
            ).status_code
            == 403
        )
    # no key or a wrong one: 401, as before keys had scopes
    for headers in ({}, _bearer("wrong")):
        r = client.post(stop, headers=headers)
        assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
        assert client.get("/api/keys", headers=headers).status_code == 401


def test_reads_beyond_loopback_take_a_key_of_any_scope(tmp_path):
    with running_app(make_settings(tmp_path, host="0.0.0.0")) as c:
        read = _make_key(c, "viewer", "read")
        assert c.get("/api/motion").status_code == 401
        assert c.get("/api/motion", headers=_bearer(read)).status_code == 200
        assert c.post("/api/motion/stop", headers=_bearer(read)).status_code == 403


def test_keys_are_listed_without_the_key_and_revoked_over_http(client):
    key = _make_key(client, "temp", "operate")
    listed = client.get("/api/keys", headers=AUTH).json()
    assert [(k["name"], k["scope"]) for k in listed] == [("admin", "admin"), ("temp", "operate")]
    assert key not in str(listed) and TOKEN not in str(listed)
    assert all(set(k) == {"name", "scope", "created_at", "revoked_at"} for k in listed)
    r = client.delete("/api/keys/temp", headers=AUTH)
    assert r.status_code == 200 and r.json()["revoked_at"] is not None
    assert client.post("/api/motion/stop", headers=_bearer(key)).status_code == 401
    r = client.delete("/api/keys/temp", headers=AUTH)
    assert r.status_code == 404 and r.json()["detail"] == "no active key named 'temp'"
    r = client.post("/api/keys", json={"name": "temp", "scope": "read"}, headers=AUTH)
    assert r.status_code == 409 and "exists already" in r.json()["detail"]
    r = client.post("/api/keys", json={"name": "TOFPOSE_API_TOKEN", "scope": "read"}, headers=AUTH)
    assert r.status_code == 409 and "reserved" in r.json()["detail"]
    for bad in (
        {"name": "has space", "scope": "read"},
        {"name": "ok", "scope": "root"},
        {"name": "ok"},
        {"name": "ok", "scope": "read", "key": "mine"},
    ):
        assert client.post("/api/keys", json=bad, headers=AUTH).status_code == 422, bad


def test_every_state_change_is_audited_answered_or_refused(client):
    read = _make_key(client, "viewer", "read")
    catalog = {"name": "tri", "reflectors": TRIANGLE}
    steps = [
        ("post", "/api/motion/stop", {}, None, 401, None),
        ("post", "/api/motion/stop", _bearer("wrong"), None, 401, None),
        ("post", "/api/motion/stop", _bearer(read), None, 403, "viewer"),
        ("post", "/api/motion/move", AUTH, {"yaw_deg": "ten"}, 422, "admin"),
        ("post", "/api/catalogs", AUTH, catalog, 201, "admin"),
        ("post", "/api/catalogs", AUTH, catalog, 409, "admin"),
        ("put", "/api/camera/settings", AUTH, {"frame_rate_hz": 15.0}, 200, "admin"),
        ("delete", "/api/keys/viewer", AUTH, None, 200, "admin"),
    ]
    for method, path, headers, body, code, _ in steps:
        assert client.request(method, path, headers=headers, json=body).status_code == code, path
    client.get("/api/motion", headers=AUTH)  # reads are not audited
    entries = _audit(client)
    # the first entry is the key's creation, by the test's configured token (stored at the
    # first start as the admin key named "admin")
    first = entries[-1]
    assert (first["method"], first["path"], first["status"]) == ("POST", "/api/keys", 201)
    assert first["body"] == '{"name":"viewer","scope":"read"}'
    got = [(e["method"].lower(), e["path"], e["status"], e["key_name"]) for e in entries[-2::-1]]
    assert got == [(m, p, code, name) for m, p, _, _, code, name in steps]
    assert all(e["client"] == "testclient" for e in entries)
    by_path = {(e["path"], e["status"]): e for e in entries}
    assert by_path[("/api/motion/move", 422)]["body"] == '{"yaw_deg":"ten"}'
    assert by_path[("/api/catalogs", 201)]["body"].startswith('{"name":"tri","reflectors":[')
    ids = [e["id"] for e in entries]
    assert ids == sorted(ids, reverse=True)


def test_secrets_in_bodies_are_redacted_and_refusals_before_any_route_recorded(client):
    r = client.post(
        "/api/keys", json={"name": "n", "scope": "read", "api_key": "hunter2"}, headers=AUTH
    )
    assert r.status_code == 422
    r = client.post("/api/motion/stop", headers={**AUTH, "Host": "evil.example"})
    assert r.status_code == 400  # a Host this server does not serve (DNS rebinding)
    entries = _audit(client)
    assert "hunter2" not in str(entries)
    assert entries[1]["body"] == '{"name":"n","scope":"read","api_key":"***"}'
    assert (entries[0]["path"], entries[0]["status"], entries[0]["key_name"]) == (
        "/api/motion/stop",
        400,
        None,
    )


def test_the_audit_trail_pages_newest_first_and_survives_a_restart(settings):
    with running_app(settings) as c:
        for _ in range(7):
            assert c.post("/api/motion/stop", headers=AUTH).status_code == 200
        c.app.state.tofpose.audit.flush()
    with running_app(settings) as c:
        first = c.get("/api/audit", params={"limit": 3}, headers=AUTH).json()
        assert [e["id"] for e in first] == [7, 6, 5]
        rest = c.get("/api/audit", params={"before_id": 5}, headers=AUTH).json()
        assert [e["id"] for e in rest] == [4, 3, 2, 1]
        assert all(e["at"].endswith("Z") or e["at"].endswith("+00:00") for e in rest)
        for bad in ({"limit": 0}, {"limit": 1001}, {"before_id": 0}, {"limit": "x"}):
            assert c.get("/api/audit", params=bad, headers=AUTH).status_code == 422, bad


def test_stop_answers_while_every_worker_thread_is_taken(client):
    """All of AnyIO's worker threads held (as a burst of exports would hold them): STOP
    still answers, because its route and every dependency it has are async and its
    driver command runs on a lane of its own; a sync route waits."""
    holders: list[object] = []

    async def take_all_threads() -> int:
        limiter = anyio.to_thread.current_default_thread_limiter()
        while limiter.available_tokens:
            holder = object()
            await limiter.acquire_on_behalf_of(holder)
            holders.append(holder)
        return int(limiter.total_tokens)

    async def give_back() -> None:
        limiter = anyio.to_thread.current_default_thread_limiter()
        while holders:
            limiter.release_on_behalf_of(holders.pop())

    assert client.portal.call(take_all_threads) == len(holders) > 0
    with ThreadPoolExecutor(2) as pool:
        try:
            stop = pool.submit(client.post, "/api/motion/stop", headers=AUTH)
            sync_read = pool.submit(client.get, "/api/motion")  # a sync route: waits
            assert stop.result(timeout=60).status_code == 200
            assert not sync_read.done()
        finally:
            client.portal.call(give_back)
        assert sync_read.result(timeout=60).status_code == 200
