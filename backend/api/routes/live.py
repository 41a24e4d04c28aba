"""WebSocket /ws/live: every pose result as JSON at the camera rate, to many clients.

Protocol (JSON text messages):

- server -> client on connect: ``{"type": "hello", "camera": {...}, "catalog": name,
  "clock": {"monotonic_ns", "wall_ns"}}`` (the stamps' clock: a stamp's UTC ns is
  ``wall_ns + (stamp - monotonic_ns)``)
- server -> client per frame: ``{"type": "pose", "dropped": n, "sent_ns": t,
  "capture_to_sent_ms": ms, "stamps": FrameStampsPublic, "latency": FrameLatencyPublic,
  "data": PosePublic}``; ``dropped`` counts frames this client missed because it read
  too slowly; ``sent_ns`` is when this message was handed to this client's socket and
  ``stamps`` the frame's capture, arrival and pose-ready stamps (host monotonic ns);
  ``latency`` the median and 95th percentile of capture -> pose and capture -> sent
  over the last seconds and the frames dropped since the start (camera, pipeline,
  clients); ``GET /api/live/stats`` has the whole of it.
- client -> server, any time: options ``{"images": ["gray", "distance"],
  "image_every": 5, "image_step": 2, "raw": false, "points": true}``. Then every
  ``image_every``-th frame also brings ``{"type": "image", "kind", "frame_index",
  "png_base64"}`` (the image shrunk ``image_step`` times) or, with ``raw``, one binary
  message holding both images as uint16 (``backend.services.live.frame_codec``; the browser
  colour-maps them). Images are skipped, never queued, when a newer frame is already
  waiting for this client (its pose messages still all go out). Raw frames are also
  flow-controlled: at most ``raw_credit`` (default 2; 0 = no limit) may be unacknowledged;
  the client acknowledges each raw frame it has drawn with ``{"ack": frame_index}``, so
  a slow browser gets fewer, newer frames instead of a queue in the socket buffers.
  Every frame brings
  ``{"type": "points", "frame_index",
  "points_mm": [[x, y, z], ...], "catalog_ids": [id or null, ...]}`` (the reflector point
  cloud in the camera frame). Bad options get ``{"type": "error", "message"}``.
- server -> client, whenever a campaign's progress changed (checked once per frame):
  ``{"type": "campaign", "data": {campaign_id, name, status, setpoint_index, n_setpoints,
  n_done, frames_collected, frames_per_point, elapsed_s, eta_s}}``.

Authentication: when reads are not open (server bound beyond loopback), a key of any
scope is needed. It travels in the handshake as a subprotocol, never in the URL (which
access logs and proxies record): offer the two subprotocols ``tofpose.bearer`` and
``tofpose.bearer.<key>`` (a browser: ``new WebSocket(url, ["tofpose.bearer",
"tofpose.bearer." + key])``); the server accepts with ``tofpose.bearer``, never echoing
the key. A key that is offered is checked also when reads are open. A URL with
``?token=`` (or ``?key=``) is refused (close code 1008) with a reason saying so.

Caps: at most ``live_max_clients_per_address`` connections from one client address and
``live_max_clients`` in all; one more is accepted and closed at once with code 1013
("try again later") and a reason naming the cap.

Clients that do not read: every message goes out through one ``send`` with a timeout
(``live_send_timeout_s``); a client whose socket has not taken a message by then is let
go (its connection slot freed; the server writes nothing more to it). Until then the
frames it cannot take are dropped from its bounded mailbox (``dropped``), and the JSON
of each frame is built once for all clients (``LiveSample.cached``).
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import time
from collections import deque
from urllib.parse import urlsplit

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from backend.api.deps import ReadAuth, StateDep
from backend.api.presenters import pose_public
from backend.api.schemas.latency import (
    ClockAnchorPublic,
    DroppedFramesPublic,
    FrameLatencyPublic,
    FrameStampsPublic,
    LatencySummaryPublic,
    LiveClientPublic,
    LiveStatsPublic,
)
from backend.api.schemas.live import LiveOptions
from backend.services.live.acquisition import LiveSample, frame_point_cloud_mm
from backend.services.live.frame_codec import encode_raw_frame
from backend.services.live.latency import DropCounts, LatencySummary, capture_source
from backend.state import AppState

log = logging.getLogger("tofpose.server")
router = APIRouter(tags=["live"])
POLICY_VIOLATION = 1008
TRY_AGAIN_LATER = 1013
SUBPROTOCOL = "tofpose.bearer"
KEY_PREFIX = SUBPROTOCOL + "."
URL_SECRETS = ("token", "key")


def pose_json(sample: LiveSample) -> str:
    return sample.cached("pose_json", lambda: pose_public(sample).model_dump_json())


def _summary(s: LatencySummary) -> LatencySummaryPublic:
    return LatencySummaryPublic(median_ms=s.median_ms, p95_ms=s.p95_ms, n=s.n)


def _dropped(d: DropCounts) -> DroppedFramesPublic:
    return DroppedFramesPublic(camera=d.camera, pipeline=d.pipeline, clients=d.clients)


def live_stats(state: AppState) -> LiveStatsPublic:
    """The latency statistics now (``LiveStatistics.snapshot``) with the live clients."""
    snap = state.acquisition.latency.snapshot()
    latest = state.acquisition.latest
    from_device = latest is None or latest.stamps is None or latest.stamps.capture_from_device
    return LiveStatsPublic(
        window_s=snap.window_s,
        frames_in_window=snap.frames_in_window,
        frames_total=snap.frames_total,
        capture_source=capture_source(state.acquisition.camera.name, from_device),
        capture_to_arrival=_summary(snap.capture_to_arrival),
        capture_to_pose=_summary(snap.capture_to_pose),
        capture_to_sent=_summary(snap.capture_to_sent),
        dropped_in_window=_dropped(snap.dropped_in_window),
        dropped_total=_dropped(snap.dropped_total),
        clock=ClockAnchorPublic(monotonic_ns=snap.anchor.monotonic_ns, wall_ns=snap.anchor.wall_ns),
        clients=[
            LiveClientPublic(address=sub.label, offered=sub.offered, dropped=sub.dropped)
            for sub in state.hub.subscriptions()
            if sub.label is not None
        ],
    )


@router.get("/api/live/stats", dependencies=[ReadAuth], tags=["status"])
def get_live_stats(state: StateDep) -> LiveStatsPublic:
    """Latency of the live stream over a sliding window (median and 95th percentile of
    capture -> arrival, capture -> pose ready, capture -> WebSocket sent; stamps on the
    host's monotonic clock, ``clock`` anchors them to UTC) and the frames dropped by the
    camera, the pipeline and the live clients (docs/server.md, "Latency and dropped
    frames")."""
    return live_stats(state)


def frame_stamps_json(sample: LiveSample) -> str:
    """The frame's stamps (``FrameStampsPublic``), "null" for a sample without any."""

    def make() -> str:
        st = sample.stamps
        if st is None:
            return "null"
        return FrameStampsPublic(
            capture_ns=st.capture_ns,
            arrival_ns=st.arrival_ns,
            pose_ready_ns=st.pose_ready_ns,
            capture_from_device=st.capture_from_device,
            capture_to_pose_ms=st.capture_to_pose_ms,
        ).model_dump_json()

    return sample.cached("stamps_json", make)


def frame_latency_json(sample: LiveSample, state: AppState) -> str:
    """The window's statistics as this frame goes out (``FrameLatencyPublic``): made
    once per frame, by its first client."""

    def make() -> str:
        snap = state.acquisition.latency.snapshot()
        return FrameLatencyPublic(
            capture_to_pose=_summary(snap.capture_to_pose),
            capture_to_sent=_summary(snap.capture_to_sent),
            dropped_total=_dropped(snap.dropped_total),
            window_s=snap.window_s,
        ).model_dump_json()

    return sample.cached("latency_json", make)


def pose_message(sample: LiveSample, state: AppState, dropped: int) -> tuple[str, int]:
    """A client's pose message for ``sample`` and the ``sent_ns`` stamped in it (the
    moment it is handed to the socket, taken as it is made)."""
    sent_ns = time.monotonic_ns()
    st = sample.stamps
    to_sent = "null" if st is None else f"{st.capture_to_sent_ms(sent_ns):.3f}"
    head = (
        f'{{"type":"pose","dropped":{dropped},"sent_ns":{sent_ns},'
        f'"capture_to_sent_ms":{to_sent},"stamps":{frame_stamps_json(sample)},'
        f'"latency":{frame_latency_json(sample, state)},"data":'
    )
    return head + pose_json(sample) + "}", sent_ns


async def image_message(sample: LiveSample, state: AppState, kind: str, step: int) -> str:
    f = sample.frame
    fut = state.renderer.stream_png(
        f.index,
        kind,
        f.gray,
        f.distance_mm,
        step,
        full_scale_counts=state.acquisition.camera.model.full_scale_counts,
    )
    index, png = await asyncio.wrap_future(fut)
    return json.dumps(
        {
            "type": "image",
            "kind": kind,
            "frame_index": index,
            "step": step,
            "png_base64": base64.b64encode(png).decode(),
        }
    )


def raw_message(sample: LiveSample, step: int, full_scale_counts: float) -> bytes:
    f = sample.frame
    return sample.cached(
        f"raw:{step}",
        lambda: encode_raw_frame(
            f.index, f.gray, f.distance_mm, step, full_scale_counts=full_scale_counts
        ),
    )


def points_message(sample: LiveSample, state: AppState) -> str:
    def make() -> str:
        pts, ids = frame_point_cloud_mm(sample, state.devices.camera.model)
        return json.dumps(
            {
                "type": "points",
                "frame_index": sample.frame.index,
                "points_mm": [[round(float(c), 2) for c in p] for p in pts],
                "catalog_ids": ids,
            }
        )

    return sample.cached("points", make)


class RawFlow:
    """Raw frames sent and not yet acknowledged by the client."""

    def __init__(self) -> None:
        self.unacked: deque[int] = deque()

    def ack(self, frame_index: int) -> None:
        while self.unacked and self.unacked[0] <= frame_index:
            self.unacked.popleft()

    def may_send(self, credit: int) -> bool:
        return credit == 0 or len(self.unacked) < credit


def _ack_index(text: str) -> int | None:
    """The frame index of an ``{"ack": n}`` message, else None."""
    if '"ack"' not in text:
        return None
    try:
        msg = json.loads(text)
    except ValueError:
        return None
    if isinstance(msg, dict) and msg.keys() == {"ack"} and type(msg["ack"]) is int:
        return msg["ack"]
    return None


async def _read_options(ws: WebSocket, opts: dict[str, LiveOptions], flow: RawFlow) -> None:
    while True:
        msg = await ws.receive()
        if msg["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(msg.get("code", 1000))
        text = msg.get("text") or (msg.get("bytes") or b"").decode("utf-8", "replace")
        if (acked := _ack_index(text)) is not None:
            flow.ack(acked)
            continue
        try:
            opts["current"] = LiveOptions.model_validate_json(text)
        except ValidationError as exc:
            problems = "; ".join(
                f"{'.'.join(map(str, e['loc'])) or 'body'}: {e['msg']}" for e in exc.errors()
            )
            await ws.send_text(json.dumps({"type": "error", "message": f"bad options: {problems}"}))


def origin_allowed(origin: str | None, host: str | None, allowed: list[str]) -> bool:
    """A browser's WebSocket is accepted from the server's own origin (the dashboard) or
    an allow-listed one; clients that send no Origin (scripts, not browsers) pass."""
    if origin is None:
        return True
    parts = urlsplit(origin)
    if f"{parts.scheme}://{parts.netloc}".lower() in allowed:
        return True
    return (
        parts.scheme in ("http", "https")
        and host is not None
        and (parts.netloc.lower() == host.lower())
    )


def offered_key(subprotocols: list[str]) -> str | None:
    """The key a client offers as the subprotocol ``tofpose.bearer.<key>``, or None."""
    for p in subprotocols:
        if p.startswith(KEY_PREFIX):
            return p[len(KEY_PREFIX) :]
    return None


def auth_refusal(ws: WebSocket, state: AppState) -> str | None:
    """Why this handshake is refused (close code 1008), or None to go on."""
    if any(name in ws.query_params for name in URL_SECRETS):
        return (
            "API key in the URL refused (URLs land in access logs): offer the "
            "subprotocols 'tofpose.bearer' and 'tofpose.bearer.<key>' instead"
        )
    key_text = offered_key(ws.scope.get("subprotocols", []))
    if key_text is not None and state.keys.verify(key_text) is None:
        return "invalid API key (unknown or revoked)"
    if key_text is None and not state.settings.reads_are_open:
        return (
            "API key required: offer the subprotocols 'tofpose.bearer' and 'tofpose.bearer.<key>'"
        )
    return None


def cap_refusal(state: AppState, address: str) -> str | None:
    """Why one more /ws/live client from ``address`` is refused (close code 1013)."""
    s = state.settings
    if sum(state.live_clients.values()) >= s.live_max_clients:
        return f"too many live clients ({s.live_max_clients}, TOFPOSE_LIVE_MAX_CLIENTS)"
    if state.live_clients.get(address, 0) >= s.live_max_clients_per_address:
        return (
            f"too many live clients from {address[:64]} ({s.live_max_clients_per_address}, "
            "TOFPOSE_LIVE_MAX_CLIENTS_PER_ADDRESS)"
        )
    return None


class SendTimeoutError(Exception):
    """The client did not take a message within ``live_send_timeout_s``."""


async def send(ws: WebSocket, message: str | bytes, timeout_s: float) -> None:
    """Send one message, giving up after ``timeout_s`` (SendTimeoutError): a client whose
    socket is full would otherwise hold its task (and connection slot) forever."""
    try:
        async with asyncio.timeout(timeout_s):
            if isinstance(message, bytes):
                await ws.send_bytes(message)
            else:
                await ws.send_text(message)
    except TimeoutError:
        raise SendTimeoutError from None


def close_reason(text: str) -> str:
    """``text`` cut to what a WebSocket close frame carries (RFC 6455 5.5: a control
    frame's payload is at most 125 bytes, 2 of them the code): at most 123 UTF-8 bytes;
    a longer reason makes the client fail the connection without reading the code."""
    raw = text.encode()
    return text if len(raw) <= 123 else raw[:120].decode(errors="ignore") + "..."


@router.websocket("/ws/live")
async def live(ws: WebSocket) -> None:
    state: AppState = ws.app.state.tofpose
    origin = ws.headers.get("origin")
    if not origin_allowed(origin, ws.headers.get("host"), state.settings.allowed_origins):
        await ws.close(
            code=POLICY_VIOLATION,
            reason=f"cross-origin WebSocket refused: {(origin or '')[:100]} "
            "(TOFPOSE_ALLOWED_ORIGINS)",
        )
        return
    subprotocol = SUBPROTOCOL if SUBPROTOCOL in ws.scope.get("subprotocols", []) else None
    if (refusal := auth_refusal(ws, state)) is not None:
        # accepted first (nothing is sent but the close), so that a browser gets the close
        # code and the reason instead of a bare failed handshake
        await ws.accept(subprotocol=subprotocol)
        await ws.close(code=POLICY_VIOLATION, reason=close_reason(refusal))
        return
    address = ws.client.host if ws.client else ""
    if (refusal := cap_refusal(state, address)) is not None:
        # accepted first, so that the client gets the close code and its reason (a close
        # before the handshake reaches a browser as a bare failed handshake)
        await ws.accept(subprotocol=subprotocol)
        await ws.close(code=TRY_AGAIN_LATER, reason=close_reason(refusal))
        return
    state.live_clients[address] = state.live_clients.get(address, 0) + 1
    try:
        await ws.accept(subprotocol=subprotocol)
        await _stream(ws, state)
    except SendTimeoutError:
        log.info(
            "live client %s let go: it took no message for %.1f s",
            address,
            state.settings.live_send_timeout_s,
        )
    finally:
        state.live_clients[address] -= 1
        if not state.live_clients[address]:
            del state.live_clients[address]


async def _stream(ws: WebSocket, state: AppState) -> None:
    """The hello, then every frame's messages until the client goes or stops reading."""
    timeout_s = state.settings.live_send_timeout_s
    m = state.devices.camera.model
    await send(
        ws,
        json.dumps(
            {
                "type": "hello",
                "catalog": state.acquisition.catalog_name,
                # the stamps' clock against UTC: wall_ns + (stamp - monotonic_ns)
                "clock": {
                    "monotonic_ns": state.acquisition.latency.anchor.monotonic_ns,
                    "wall_ns": state.acquisition.latency.anchor.wall_ns,
                },
                "camera": {
                    "driver": state.devices.camera.name,
                    "width_px": m.width,
                    "height_px": m.height,
                    "full_scale_counts": m.full_scale_counts,
                    "fx_px": m.fx,
                    "fy_px": m.fy,
                    "cx_px": m.cx,
                    "cy_px": m.cy,
                },
            }
        ),
        timeout_s,
    )
    latency = state.acquisition.latency
    address = ws.client.host if ws.client else ""
    sub = state.hub.subscribe(
        loop=asyncio.get_running_loop(), label=address, on_drop=latency.record_client_drops
    )
    opts = {"current": LiveOptions()}
    flow = RawFlow()
    reader = asyncio.create_task(_read_options(ws, opts, flow))
    n = 0
    campaign_version = -1
    try:
        while True:
            getter = asyncio.ensure_future(sub.get_async())
            done, _ = await asyncio.wait({getter, reader}, return_when=asyncio.FIRST_COMPLETED)
            if reader in done:
                getter.cancel()
                reader.result()  # re-raises the disconnect
                return
            sample: LiveSample = getter.result()
            message, sent_ns = pose_message(sample, state, sub.dropped)
            await send(ws, message, timeout_s)
            if sample.stamps is not None:
                latency.record_sent(sample.stamps, sent_ns)
            if (v := state.campaigns.progress_version) != campaign_version:
                campaign_version = v
                if (progress := state.campaigns.progress()) is not None:
                    await send(ws, json.dumps({"type": "campaign", "data": progress}), timeout_s)
            o = opts["current"]
            # Images only for the newest frame: if another is already waiting, this one's
            # images would only delay it (latest frame wins; poses are never skipped).
            if n % o.image_every == 0 and not sub.pending and sample.has_images:
                if o.raw and flow.may_send(o.raw_credit):
                    flow.unacked.append(sample.frame.index)
                    full_scale = state.acquisition.camera.model.full_scale_counts
                    await send(ws, raw_message(sample, o.image_step, full_scale), timeout_s)
                for kind in o.images if not o.raw else ():
                    text = await image_message(sample, state, kind, o.image_step)
                    await send(ws, text, timeout_s)
            if o.points:
                await send(ws, points_message(sample, state), timeout_s)
            n += 1
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        state.hub.unsubscribe(sub)
        reader.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await reader
