"""Both Foxglove WebSocket subprotocols on one port, in front of the ``foxglove-sdk`` server.

``foxglove-sdk`` (0.30) accepts only its own subprotocols (``foxglove.sdk.v1``,
``foxglove.sdk.v1.1``) and answers HTTP 400 to a client of the open protocol,
``foxglove.websocket.v1`` (the ``@foxglove/ws-protocol`` client library, Lichtblick,
older Foxglove apps). The SDK's ``foxglove.sdk.v1`` is the same protocol under a new
name (Foxglove's own statement; the SDK has no option to accept the old name), so this
relay listens on the public port, and for each client:

1. before answering the client's handshake, opens a connection to the SDK server on
   loopback offering the client's subprotocols, with ``foxglove.websocket.v1``
   offered as ``foxglove.sdk.v1`` (``upstream_offer``);
2. answers with the subprotocol the SDK chose, under the name the client offered
   (``client_subprotocol``): a ``foxglove.websocket.v1`` client is told
   ``foxglove.websocket.v1``, an SDK client gets what the SDK picked;
3. forwards every frame both ways unchanged (text and binary), so the SDK keeps its
   per-client backlog: a client that reads slowly stops this relay reading from the
   SDK, and the SDK drops that client's oldest messages.

A client that offers neither gets HTTP 400 naming the subprotocols served.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Sequence
from http import HTTPStatus

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

log = logging.getLogger("tofpose.foxglove")

OPEN_PROTOCOL = "foxglove.websocket.v1"
SDK_PROTOCOL = "foxglove.sdk.v1"
SERVED_SUBPROTOCOLS = (SDK_PROTOCOL, OPEN_PROTOCOL)
"""What a client may offer; the SDK's later ``foxglove.sdk.*`` versions pass through."""


def upstream_offer(offered: Sequence[str]) -> list[str]:
    """The subprotocols to offer the SDK for a client that offered ``offered``.

    The SDK's own names (``foxglove.sdk.*``) pass in the client's order; the open
    protocol's name becomes ``foxglove.sdk.v1`` (the same protocol). Empty when the
    client offered no Foxglove subprotocol.
    """
    out: list[str] = []
    for p in offered:
        name = SDK_PROTOCOL if p == OPEN_PROTOCOL else p
        if name.startswith("foxglove.sdk.") and name not in out:
            out.append(name)
    return out


def client_subprotocol(offered: Sequence[str], chosen_upstream: str) -> str:
    """The name to answer the client with, given what the SDK chose.

    The SDK's choice when the client offered it; else the client offered only the open
    protocol's name for it, and gets that name back.
    """
    if chosen_upstream in offered:
        return chosen_upstream
    if chosen_upstream == SDK_PROTOCOL and OPEN_PROTOCOL in offered:
        return OPEN_PROTOCOL
    raise ValueError(f"the SDK chose {chosen_upstream!r}, which the client did not offer")


def _bad_request(text: str) -> Response:
    body = text.encode()
    headers = Headers([("Content-Type", "text/plain; charset=utf-8")])
    headers["Content-Length"] = str(len(body))
    return Response(HTTPStatus.BAD_REQUEST.value, HTTPStatus.BAD_REQUEST.phrase, headers, body)


class FoxgloveRelay:
    """Listens on ``host:port`` and relays each client to the SDK server at ``upstream_url``.

    Runs its own asyncio loop in a daemon thread; ``port`` is the bound port (useful with
    ``port=0``). Raises ``OSError`` from the constructor when the port cannot be bound.
    """

    def __init__(self, *, host: str, port: int, upstream_url: str) -> None:
        self.upstream_url = upstream_url
        self.clients = 0
        self._upstreams: dict[int, ClientConnection] = {}
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(
            target=self._run, args=(host, port), name="tofpose-foxglove-relay", daemon=True
        )
        self._thread.start()
        self._ready.wait(timeout=10.0)
        if self._error is not None:
            raise self._error
        if self._server is None:
            raise OSError(f"Foxglove relay did not start on {host}:{port}")

    @property
    def port(self) -> int:
        assert self._server is not None
        return int(self._server.sockets[0].getsockname()[1])

    def close(self) -> None:
        if self._server is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._server.close)
        self._thread.join(timeout=5.0)

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve(host, port))
        except BaseException as exc:  # noqa: BLE001 - reported to the constructor
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _serve(self, host: str, port: int) -> None:
        async with serve(
            self._relay,
            host,
            port,
            process_request=self._open_upstream,
            process_response=self._drop_unused_upstream,
            select_subprotocol=self._select,
            compression=None,  # images; the SDK does not compress either
            max_size=2**20,  # client -> server: subscriptions, small JSON
            # no keepalive pings of the relay's own, on either side: a pong queued behind
            # images a slow client has not read yet would time out and cut a client the
            # SDK alone would keep (feeding it its newest messages)
            ping_interval=None,
        ) as server:
            self._server = server
            self._ready.set()
            await server.wait_closed()

    async def _open_upstream(
        self, connection: ServerConnection, request: Request
    ) -> Response | None:
        offered = [
            p.strip()
            for value in request.headers.get_all("Sec-WebSocket-Protocol")
            for p in value.split(",")
            if p.strip()
        ]
        offer = upstream_offer(offered)
        if not offer:
            return _bad_request(
                "Foxglove WebSocket: offer one of the subprotocols "
                f"{', '.join(SERVED_SUBPROTOCOLS)} (offered: {', '.join(offered) or 'none'})\n"
            )
        try:
            upstream = await connect(
                self.upstream_url,
                subprotocols=[Subprotocol(p) for p in offer],
                compression=None,
                max_size=None,  # images of any camera's size
                # a couple of messages buffered here, not 16 images: a client that stops
                # reading soon stops the relay reading, and the SDK drops its oldest
                max_queue=2,
                ping_interval=None,  # loopback to this process's own SDK server
                open_timeout=5.0,
            )
        except Exception as exc:  # noqa: BLE001 - the client is told why
            log.warning("Foxglove relay: the SDK server refused a client: %s", exc)
            return _bad_request(f"Foxglove WebSocket: the live server refused: {exc}\n")
        self._upstreams[id(connection)] = upstream
        return None

    def _select(
        self, connection: ServerConnection, subprotocols: Sequence[Subprotocol]
    ) -> Subprotocol | None:
        upstream = self._upstreams.get(id(connection))
        if upstream is None or upstream.subprotocol is None:
            return None
        return Subprotocol(client_subprotocol(subprotocols, upstream.subprotocol))

    async def _drop_unused_upstream(
        self, connection: ServerConnection, request: Request, response: Response
    ) -> None:
        if response.status_code != HTTPStatus.SWITCHING_PROTOCOLS:
            upstream = self._upstreams.pop(id(connection), None)
            if upstream is not None:
                await upstream.close()

    async def _relay(self, client: ServerConnection) -> None:
        upstream = self._upstreams.pop(id(client))
        self.clients += 1

        async def pump(
            src: ClientConnection | ServerConnection, dst: ClientConnection | ServerConnection
        ) -> None:
            with contextlib.suppress(ConnectionClosed):
                async for message in src:
                    await dst.send(message)

        tasks = [
            asyncio.create_task(pump(upstream, client)),
            asyncio.create_task(pump(client, upstream)),
        ]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            await upstream.close()
            await client.close()
            self.clients -= 1
