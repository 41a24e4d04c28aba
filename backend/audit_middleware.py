"""The audit middleware (pure ASGI): records every state-changing HTTP request, answered
or refused, through ``backend.services.audit.AuditService``.

It sits outside every other middleware, so a request refused before any route runs (a
Host the server does not serve, a body over the limit) is recorded too. On the event
loop it only copies the body chunks the app reads (the first ``BODY_BYTES_KEPT`` bytes),
notes the status the app answers with, and hands the entry to the service's queue; the
body summary and the database write happen on the audit writer thread. The key name
comes from the auth dependency, which leaves it in the scope's ``state``
(``KEY_NAME_STATE``); a request without a valid key is recorded with none.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.services.audit import (
    AUDITED_METHODS,
    BODY_BYTES_KEPT,
    KEY_NAME_STATE,
    AuditEntry,
    AuditService,
)


class AuditMiddleware:
    """Record each POST, PUT, PATCH and DELETE with ``audit(app)``'s service, looked up
    per request (the service is built by the lifespan, after the middleware)."""

    def __init__(self, app: ASGIApp, audit: Any) -> None:
        self.app = app
        self.audit = audit  # a callable returning the AuditService, or None before start

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] not in AUDITED_METHODS:
            await self.app(scope, receive, send)
            return
        at = datetime.now(UTC)
        state = scope.setdefault("state", {})
        chunks: list[bytes] = []
        seen = [0, 500]  # body bytes read, status answered (500 until the app answers)

        async def receive_copy() -> Message:
            message = await receive()
            if message["type"] == "http.request":
                body = message.get("body", b"")
                if seen[0] < BODY_BYTES_KEPT:
                    chunks.append(body[: BODY_BYTES_KEPT - seen[0]])
                seen[0] += len(body)
            return message

        async def send_status(message: Message) -> None:
            if message["type"] == "http.response.start":
                seen[1] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive_copy, send_status)
        finally:
            service: AuditService | None = self.audit()
            if service is not None:
                client = scope.get("client")
                service.record(
                    AuditEntry(
                        at=at,
                        key_name=state.get(KEY_NAME_STATE),
                        client=client[0] if client else "",
                        method=scope["method"],
                        path=scope["path"],
                        status=seen[1],
                        body=b"".join(chunks),
                        body_size=seen[0],
                    )
                )
