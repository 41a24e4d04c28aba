"""The 3-D scene's port answers the main port's names and origins only: a real LiveScene
on a free loopback port, reached with the ``websockets`` client (the protocol a browser
speaks, viser's subprotocol offered) and with plain HTTP. A foreign Origin or a foreign
Host is refused before the WebSocket opens (so no scene message can be sent on it); the
dashboard's origin and the scene's own page get the scene, whose nodes are decoded
from viser's messages."""

from __future__ import annotations

import http.client
import socket

import msgspec
import pytest
import viser
import websockets.asyncio.server
import zstandard
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from backend.services.live.scene import LiveScene, SceneAccess, split_host
from tests.backend.conftest import make_settings, running_app

DASHBOARD_PORT = 8000  # make_settings' main port: the dashboard's origin is on it
NODES = {"/camera", "/camera/frustum", "/camera/cloud", "/turntable", "/lab"}


@pytest.fixture(scope="module")
def app_scene(tmp_path_factory):
    """The scene as the app starts it (``_start_scene``: the settings' names and origins)."""
    settings = make_settings(tmp_path_factory.mktemp("data"), viser=True, viser_port=0)
    assert settings.port == DASHBOARD_PORT
    with running_app(settings) as client:
        scene = client.app.state.tofpose.scene
        assert scene is not None, client.app.state.tofpose.scene_reason
        yield client, scene


def open_scene(port: int, *, host: str | None = None, origin: str | None = None):
    """The scene's WebSocket as a browser opens it: ``host`` is the Host header (the name
    the page was loaded from), the TCP connection goes to 127.0.0.1 whatever it says."""
    sock = socket.create_connection(("127.0.0.1", port))
    return connect(
        f"ws://{host or f'127.0.0.1:{port}'}/",
        sock=sock,
        origin=origin,
        subprotocols=[f"viser-v{viser.__version__}"],
    )


def scene_nodes(ws) -> set[str]:
    """The node names in what the scene sends a new client, up to viser's end-of-replay
    marker (its whole scene as it stands)."""
    names: set[str] = set()
    while True:
        data = ws.recv()
        n_inner = int.from_bytes(data[:8], "little")
        n_packed = int.from_bytes(data[8:16], "little")
        inner = zstandard.ZstdDecompressor().decompress(data[16 : 16 + n_packed], n_inner)
        messages = msgspec.msgpack.decode(inner)["messages"]
        names |= {m["name"] for m in messages if isinstance(m.get("name"), str)}
        if any(m.get("type") == "ReplayDoneMessage" for m in messages):
            return names


def refused(port: int, **kw) -> tuple[int, str]:
    with pytest.raises(InvalidStatus) as exc:
        open_scene(port, **kw).close()
    response = exc.value.response
    return response.status_code, bytes(response.body).decode()


def http_get(port: int, host: str, headers: dict[str, str] | None = None):
    conn = http.client.HTTPConnection("127.0.0.1", port)
    try:
        conn.request("GET", "/", headers={"Host": host, **(headers or {})})
        r = conn.getresponse()
        return r.status, dict(r.getheaders()), r.read()
    finally:
        conn.close()


@pytest.mark.parametrize(
    "origin",
    [
        "http://evil.example",  # any page the lab user visits
        "http://localhost:9999",  # another local web app
        "http://127.0.0.1:8000.evil.example",
        "https://127.0.0.1:1",
        "null",  # a sandboxed frame or a file:// page
        "file://",
    ],
)
def test_a_foreign_origin_websocket_is_refused_before_it_opens(app_scene, origin):
    _, scene = app_scene
    status, text = refused(scene.port, origin=origin)
    assert status == 403 and "cross-origin" in text


def test_a_foreign_host_is_refused_on_the_websocket_and_the_page(app_scene):
    """DNS rebinding: a hostile name re-resolved to 127.0.0.1 is same-origin with itself,
    so only the Host check stops it."""
    _, scene = app_scene
    rebound = f"evil.example:{scene.port}"
    assert refused(scene.port, host=rebound, origin=f"http://{rebound}") == (
        400,
        "Invalid host header\n",
    )
    assert refused(scene.port, host=rebound)[0] == 400  # without an Origin too
    status, headers, body = http_get(scene.port, rebound)
    assert status == 400 and b"<html" not in body.lower()
    assert headers["Content-Security-Policy"] == "frame-ancestors 'none'"
    status, _, _ = http_get(scene.port, "127.0.0.1", {"Origin": "http://evil.example"})
    assert status == 403  # a page's fetch names its origin: refused like the WebSocket


@pytest.mark.parametrize(
    ("host", "origin"),
    [
        ("127.0.0.1", f"http://127.0.0.1:{DASHBOARD_PORT}"),  # the dashboard, framing it
        ("localhost", f"http://localhost:{DASHBOARD_PORT}"),  # the same, by another name
        ("127.0.0.1", "{scene}"),  # the scene's own page (its own tab, or in the frame)
        ("127.0.0.1", None),  # a script: no Origin
    ],
)
def test_the_dashboard_and_the_scenes_own_page_get_the_scene(app_scene, host, origin):
    _, scene = app_scene
    host_header = f"{host}:{scene.port}"
    if origin == "{scene}":
        origin = f"http://{host_header}"
    with open_scene(scene.port, host=host_header, origin=origin) as ws:
        assert scene_nodes(ws) >= NODES


def test_the_page_may_be_framed_by_the_dashboard_only(app_scene):
    _, scene = app_scene
    for name in ("127.0.0.1", "localhost"):
        status, headers, body = http_get(scene.port, f"{name}:{scene.port}")
        assert status == 200 and b"<html" in body.lower()  # viser's client
        dashboard = f"{name}:{DASHBOARD_PORT}"
        assert headers["Content-Security-Policy"] == (
            f"frame-ancestors http://{dashboard} https://{dashboard}"
        )
        assert headers["X-Content-Type-Options"] == "nosniff"
        assert headers["Referrer-Policy"] == "no-referrer"


def test_a_scene_with_its_own_names_and_origins(app_scene):
    """LiveScene started directly: extra names and origins pass, the defaults do not."""
    client, _ = app_scene
    state = client.app.state.tofpose
    serve = websockets.asyncio.server.serve
    scene = LiveScene(
        state.hub,
        state.acquisition,
        host="127.0.0.1",
        port=0,
        trusted_hosts=["127.0.0.1", "Bench-PC.lab"],
        allowed_origins=["http://localhost:5173/"],
        dashboard_port=8123,
    )
    try:
        assert websockets.asyncio.server.serve is serve  # the wrapper is gone again
        port = scene.port
        with open_scene(port, host=f"bench-pc.lab:{port}", origin="http://bench-pc.lab:8123"):
            pass
        with open_scene(port, origin="http://localhost:5173"):  # a Vite dev server
            pass
        assert refused(port, host=f"localhost:{port}")[0] == 400  # not in this list
        assert refused(port, origin=f"http://127.0.0.1:{DASHBOARD_PORT}")[0] == 403
        _, headers, _ = http_get(port, f"bench-pc.lab:{port}")
        assert headers["Content-Security-Policy"] == (
            "frame-ancestors http://bench-pc.lab:8123 https://bench-pc.lab:8123 "
            "http://localhost:5173"
        )
    finally:
        scene.close()


def test_a_viser_that_starts_its_server_another_way_is_not_served(app_scene, monkeypatch):
    """Were viser to reach ``serve`` by another path, the check would not be installed:
    the scene must then refuse to run rather than run unchecked."""
    from types import SimpleNamespace

    import viser.infra._infra as infra

    client, _ = app_scene
    state = client.app.state.tofpose
    real = websockets.asyncio.server
    elsewhere = SimpleNamespace(
        asyncio=SimpleNamespace(server=SimpleNamespace(serve=real.serve)),
        exceptions=infra.websockets.exceptions,
        datastructures=infra.websockets.datastructures,
    )
    monkeypatch.setattr(infra, "websockets", elsewhere)
    with socket.socket() as probe:  # a free port, to see it closed again afterwards
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(RuntimeError, match="no Host/Origin check"):
        LiveScene(state.hub, state.acquisition, host="127.0.0.1", port=port)
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", port)).close()


# -- the rules, table-driven --------------------------------------------------------------
LOOPBACK = SceneAccess(dashboard_port=8000)
LAB = SceneAccess(
    trusted_hosts=("*.lab", "10.0.0.5"), allowed_origins=("https://ops.lab",), dashboard_port=443
)
ANY = SceneAccess(trusted_hosts=("*",), dashboard_port=8000)


@pytest.mark.parametrize(
    ("access", "hosts", "origins", "expected"),
    [
        (LOOPBACK, ["127.0.0.1:8080"], [], None),
        (LOOPBACK, ["[::1]:8080"], ["http://[::1]:8000"], None),  # IPv6: the dashboard
        (LOOPBACK, ["[::1]:8080"], ["http://[::1]:8080"], None),  # IPv6: its own page
        (LOOPBACK, ["LOCALHOST:8080"], ["http://localhost:8000"], None),  # case
        (LOOPBACK, ["127.0.0.1:8080"], ["http://localhost:8000"], 403),  # another name
        (LOOPBACK, ["127.0.0.1:8080"], ["http://127.0.0.1:8001"], 403),
        (LOOPBACK, ["127.0.0.1:8080"], ["http://127.0.0.1"], 403),  # port 80
        (LOOPBACK, ["127.0.0.1:8080"], ["ws://127.0.0.1:8080"], 403),  # not a page
        (LOOPBACK, ["127.0.0.1:8080"], ["http://[::1"], 403),  # unparsable
        (LOOPBACK, ["127.0.0.1:8080"], ["http://127.0.0.1:8000"] * 2, 403),  # repeated
        (LOOPBACK, ["127.0.0.1:8080", "evil.example"], [], 400),  # repeated Host
        (LOOPBACK, [], [], 400),  # no Host
        (LOOPBACK, ["127.0.0.1:8080;x"], [], 400),  # not a host name
        (LOOPBACK, ["127.0.0.2:8080"], [], 400),  # loopback, but not a served name
        (LAB, ["scope.bench.lab:8080"], ["https://scope.bench.lab"], None),  # 443
        (LAB, ["10.0.0.5:8080"], ["https://ops.lab"], None),  # allow-listed
        (LAB, ["lab:8080"], [], 400),  # "*.lab" is its sub-domains only
        (LAB, ["evil.example:8080"], ["https://ops.lab"], 400),
        (ANY, ["whatever.example:8080"], ["http://whatever.example:8000"], None),
        (ANY, ["whatever.example:8080"], ["http://other.example:8000"], 403),
        (ANY, [], ["http://evil.example"], 403),
    ],
)
def test_the_rules(access, hosts, origins, expected):
    result = access.refusal(hosts, origins)
    assert (None if result is None else result.status) == expected


def test_host_headers_are_split_like_the_main_servers():
    assert split_host("LocalHost:8080") == ("localhost", 8080)
    assert split_host("[::1]") == ("[::1]", None)
    assert split_host("bench_pc.lab") == ("bench_pc.lab", None)
    for bad in ("", "a b", "a:b", "evil.example/x", "user@host", "host;frame-ancestors *"):
        assert split_host(bad) is None, bad


def test_the_frame_ancestors_name_only_the_dashboard():
    assert LOOPBACK.frame_ancestors(["localhost:8080"]) == (
        "frame-ancestors http://localhost:8000 https://localhost:8000"
    )
    assert LOOPBACK.frame_ancestors(["evil.example"]) == "frame-ancestors 'none'"
    assert SceneAccess().frame_ancestors(["127.0.0.1:8080"]) == "frame-ancestors 'none'"
    assert LAB.frame_ancestors(["x.lab:8080"]) == (
        "frame-ancestors http://x.lab:443 https://x.lab:443 https://ops.lab"
    )
