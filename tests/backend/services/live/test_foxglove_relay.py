"""Both Foxglove subprotocols on the live port: the published ``@foxglove/ws-protocol``
client (npm, not our code) with its default subprotocol ``foxglove.websocket.v1`` gets the
channel list and the live messages that the SDK's own subprotocol gets; a client offering
neither is told which to offer. The name mapping itself is table-tested."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from backend.services.live.foxglove_relay import client_subprotocol, upstream_offer
from tests.backend.conftest import make_settings, running_app, wait_for
from tofpose.io.interop import topics
from tofpose.workflows.simulation import simulate

FRONTEND = Path(__file__).resolve().parents[4] / "frontend"
CLIENT = FRONTEND / "scripts" / "foxglove-client.mjs"


@pytest.mark.parametrize(
    ("offered", "upstream"),
    [
        (["foxglove.websocket.v1"], ["foxglove.sdk.v1"]),
        (["foxglove.sdk.v1"], ["foxglove.sdk.v1"]),
        (["foxglove.sdk.v1.1", "foxglove.websocket.v1"], ["foxglove.sdk.v1.1", "foxglove.sdk.v1"]),
        (["foxglove.websocket.v1", "foxglove.sdk.v1"], ["foxglove.sdk.v1"]),
        (["chat", "graphql-ws"], []),
        ([], []),
    ],
)
def test_the_sdk_is_offered_the_clients_subprotocols_under_its_own_names(offered, upstream):
    assert upstream_offer(offered) == upstream


@pytest.mark.parametrize(
    ("offered", "chosen", "answer"),
    [
        (["foxglove.websocket.v1"], "foxglove.sdk.v1", "foxglove.websocket.v1"),
        (["foxglove.sdk.v1", "foxglove.websocket.v1"], "foxglove.sdk.v1", "foxglove.sdk.v1"),
        (["foxglove.sdk.v1.1", "foxglove.websocket.v1"], "foxglove.sdk.v1.1", "foxglove.sdk.v1.1"),
    ],
)
def test_the_client_is_answered_with_the_name_it_offered(offered, chosen, answer):
    assert client_subprotocol(offered, chosen) == answer


def test_a_choice_the_client_did_not_offer_is_named():
    with pytest.raises(ValueError, match="foxglove.sdk.v2"):
        client_subprotocol(["foxglove.websocket.v1"], "foxglove.sdk.v2")


def run_npm_client(url: str, seconds: float) -> dict:
    node = shutil.which("node")
    assert node, "node is not on PATH (the Foxglove client test needs Node.js)"
    assert (FRONTEND / "node_modules" / "@foxglove" / "ws-protocol").exists(), (
        "frontend/node_modules lacks @foxglove/ws-protocol: run `make frontend` (npm ci)"
    )
    r = subprocess.run(
        [node, "--experimental-websocket", "--no-warnings", str(CLIENT), url, str(seconds)],
        cwd=FRONTEND,
        capture_output=True,
        text=True,
        timeout=seconds + 60,
        env={**os.environ, "NO_COLOR": "1"},
    )
    assert r.returncode == 0, f"the npm client failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_published_client_gets_the_live_channels_with_its_default_subprotocol(tmp_path):
    # 20 frames/s (make_settings), 4 s: ~80 frames; the pose channel has one per measured
    # frame with a pose, so at least 20 leaves room for a loaded machine
    settings = make_settings(tmp_path / "data", foxglove_port=0)
    with running_app(settings) as c:
        info = wait_for(lambda: (r := c.get("/api/foxglove").json())["running"] and r, 10)
        assert set(info["subprotocols"]) == {"foxglove.sdk.v1", "foxglove.websocket.v1"}
        advertised = {ch.topic() for ch in c.app.state.tofpose.foxglove.channels.channels}
        report = run_npm_client(info["url"], 4.0)
        published = c.get("/api/foxglove").json()["published"]
    assert report["offered"] == report["subprotocol"] == "foxglove.websocket.v1"
    assert report["serverName"] == "tofpose"
    assert {ch["topic"] for ch in report["channels"]} == advertised
    assert len(report["channels"]) == len(advertised) == 15
    assert report["messages"].get(topics.POSE_TRANSFORM, 0) >= 20, report["messages"]
    assert report["messages"][topics.GRAY] >= 20
    # the gray image's RawImage carries the 320x240 mono16 pixels (+ a small header)
    assert 320 * 240 * 2 < report["lastBytes"][topics.GRAY] < 320 * 240 * 2 + 200
    assert report["messages"][topics.GRAY] <= published


def test_another_cameras_images_reach_the_client_whole(tmp_path):
    """A replayed Azure Kinect NFOV recording: its 640 x 576 distance image (32FC1, 1.4 MB,
    more than a WebSocket library's usual 1 MiB message limit) reaches the npm client."""
    rec = tmp_path / "ak.h5"
    simulate("stability-697", 4, str(rec), 3, None, progress=False, camera_arg="azure-kinect-nfov")
    settings = make_settings(tmp_path / "data", camera=f"replay:{rec}", foxglove_port=0)
    with running_app(settings) as c:
        info = wait_for(lambda: (r := c.get("/api/foxglove").json())["running"] and r, 10)
        report = run_npm_client(info["url"], 3.0)
    assert report["subprotocol"] == "foxglove.websocket.v1"
    assert report["messages"][topics.DISTANCE] >= 5, report["messages"]
    assert 640 * 576 * 4 < report["lastBytes"][topics.DISTANCE] < 640 * 576 * 4 + 200
    assert 640 * 576 * 2 < report["lastBytes"][topics.GRAY] < 640 * 576 * 2 + 200


def test_a_taken_port_leaves_the_server_up_with_the_reason(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with running_app(make_settings(tmp_path / "data", foxglove_port=port)) as c:
            r = c.get("/api/foxglove").json()
            assert r["running"] is False
            assert "failed to start" in r["reason"] and str(port) in r["reason"], r
            assert c.get("/api/pose/latest").status_code in (200, 404)  # the API runs


def test_a_client_offering_no_foxglove_subprotocol_is_told_which_to_offer(tmp_path):
    with running_app(make_settings(tmp_path / "data", foxglove_port=0)) as c:
        info = wait_for(lambda: (r := c.get("/api/foxglove").json())["running"] and r, 10)
        with pytest.raises(InvalidStatus) as err:
            connect(info["url"], subprotocols=["graphql-ws"], open_timeout=10)
        response = err.value.response
        assert response.status_code == 400
        body = response.body.decode()
        assert "foxglove.websocket.v1" in body and "graphql-ws" in body
        # the SDK's own subprotocols are still served on the same port, as the SDK picks
        for offered, chosen in [
            (["foxglove.sdk.v1"], "foxglove.sdk.v1"),
            (["foxglove.sdk.v1.1", "foxglove.websocket.v1"], "foxglove.sdk.v1.1"),
        ]:
            with connect(info["url"], subprotocols=offered, open_timeout=10) as ws:
                assert ws.subprotocol == chosen
                assert json.loads(ws.recv(timeout=10))["op"] == "serverInfo"


# Load: the loop's frame rate is what is measured
@pytest.mark.load_sensitive
def test_a_client_that_never_reads_does_not_slow_the_camera_loop(tmp_path):
    """Through the relay as straight to the SDK: a client subscribed to every channel that
    reads nothing for 3 s leaves the loop at its frame rate, and the publisher keeps
    publishing (the SDK drops that client's oldest messages)."""
    settings = make_settings(tmp_path / "data", foxglove_port=0)  # 20 frames/s
    with running_app(settings) as c:
        info = wait_for(lambda: (r := c.get("/api/foxglove").json())["running"] and r, 10)
        state = c.app.state.tofpose
        with connect(info["url"], subprotocols=["foxglove.websocket.v1"], open_timeout=10) as ws:
            ids: list[int] = []
            while len(ids) < 15:
                msg = json.loads(ws.recv(timeout=10))
                if msg["op"] == "advertise":
                    ids += [ch["id"] for ch in msg["channels"]]
            subs = [{"id": i, "channelId": ch} for i, ch in enumerate(ids)]
            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            time.sleep(0.5)
            frames0, published0 = state.acquisition.frames_processed, state.foxglove.published
            time.sleep(3.0)  # the client reads nothing
            frames = state.acquisition.frames_processed - frames0
            published = state.foxglove.published - published0
            assert frames >= 0.6 * 20 * 3.0, frames
            assert published >= 0.7 * frames, (published, frames)
            # and it still gets messages when it reads again
            assert any(isinstance(ws.recv(timeout=10), bytes) for _ in range(50))
