"""The live Foxglove server: a client speaking the Foxglove WebSocket protocol (not our
code: ``websockets`` + protobuf from the schema the server advertises) subscribes to the
gray image and gets the frames the server measured; off unless asked, refused beyond
loopback with closed reads."""

from __future__ import annotations

import base64
import json
import struct

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from websockets.sync.client import connect

from backend.settings import Settings
from tests.backend.conftest import make_settings, running_app, wait_for
from tofpose.io.interop import topics

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01  # binary opcode of a message on a subscribed channel


def message_class(channel: dict):
    """The protobuf class of an advertised channel, built from its FileDescriptorSet."""
    assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def receive_json(ws, op: str) -> dict:
    while True:
        msg = ws.recv(timeout=10)
        if isinstance(msg, str) and json.loads(msg)["op"] == op:
            return json.loads(msg)


def subscribe(ws, wanted: dict[str, int]) -> dict[str, dict]:
    """Subscribe to ``{topic: subscription id}`` once all are advertised."""
    seen: dict[str, dict] = {}
    while not set(wanted) <= set(seen):
        for ch in receive_json(ws, "advertise")["channels"]:
            seen[ch["topic"]] = ch
    ws.send(
        json.dumps(
            {
                "op": "subscribe",
                "subscriptions": [
                    {"id": sid, "channelId": seen[t]["id"]} for t, sid in wanted.items()
                ],
            }
        )
    )
    return seen


def test_a_foxglove_client_gets_the_frames_the_server_measured(tmp_path):
    settings = make_settings(tmp_path / "data", foxglove_port=0)
    with running_app(settings) as c:
        info = wait_for(lambda: (r := c.get("/api/foxglove").json())["running"] and r, 10)
        assert info["url"] == f"ws://127.0.0.1:{info['port']}"
        state = c.app.state.tofpose
        sub = state.hub.subscribe(maxsize=200)  # what the server measured, by time
        with connect(info["url"], subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
            assert ws.subprotocol in SUBPROTOCOLS
            assert receive_json(ws, "serverInfo")["name"] == "tofpose"
            channels = subscribe(ws, {topics.GRAY: 1, topics.POSE_TRANSFORM: 2})
            RawImage = message_class(channels[topics.GRAY])
            Transform = message_class(channels[topics.POSE_TRANSFORM])
            images, transforms = {}, {}
            while len(images) < 3 or not (set(images) & set(transforms)):
                msg = ws.recv(timeout=10)
                if isinstance(msg, str):
                    continue
                op, sid, log_ns = struct.unpack_from("<BIQ", msg)
                assert op == MESSAGE_DATA
                payload = msg[struct.calcsize("<BIQ") :]
                (images if sid == 1 else transforms)[log_ns] = (
                    RawImage if sid == 1 else Transform
                ).FromString(payload)
        # a client that shows only the 3-D pose (no image panel) gets it too: channels
        # are converted for whoever subscribes to them
        with connect(info["url"], subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
            subscribe(ws, {topics.POSE_TRANSFORM: 7})
            while isinstance(msg := ws.recv(timeout=10), str):
                pass
            assert struct.unpack_from("<BI", msg) == (MESSAGE_DATA, 7)
            tf = Transform.FromString(msg[struct.calcsize("<BIQ") :])
            assert (tf.parent_frame_id, tf.child_frame_id) == ("camera", "target")
        # stop the subscription first, then drain what it holds: draining a live one
        # with a 0.1 s wait never ends while the camera delivers a frame every 0.1 s
        state.hub.unsubscribe(sub)
        measured = {}
        while (s := sub.get(timeout_s=0.0)) is not None:
            measured[int(round(s.captured_unix_s * 1e9))] = s
        matched = compared = 0
        for log_ns, img in images.items():
            if log_ns not in measured:
                continue  # published before the test's own subscription began
            sample = measured[log_ns]
            assert (img.width, img.height, img.encoding) == (320, 240, "mono16")
            gray = np.frombuffer(img.data, "<u2").reshape(240, 320)
            np.testing.assert_array_equal(gray, sample.frame.gray)
            if log_ns in transforms and sample.result.ok:
                t = transforms[log_ns].translation
                np.testing.assert_allclose([t.x, t.y, t.z], sample.result.t_mm / 1000.0, atol=1e-12)
                compared += 1
            matched += 1
        assert matched >= 2 and compared >= 1
        status = c.get("/api/foxglove").json()
        assert status["published"] >= 3


def test_off_by_default_and_refused_beyond_loopback_with_closed_reads(tmp_path):
    with running_app(make_settings(tmp_path / "a")) as c:
        r = c.get("/api/foxglove").json()
        assert r["running"] is False and "--foxglove-port" in r["reason"]
    s = Settings(host="0.0.0.0", foxglove_port=0)
    assert "closed reads" in s.foxglove_refusal
    assert Settings(host="0.0.0.0", foxglove_port=0, open_reads=True).foxglove_refusal is None


@pytest.mark.parametrize("port", [-1, 70000])
def test_a_bad_port_is_named(port):
    with pytest.raises(ValueError, match="foxglove_port"):
        Settings(foxglove_port=port)
