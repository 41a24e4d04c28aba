"""Hardening headers on every HTTP answer of the main server (dashboard, API, docs, errors).

- ``Content-Security-Policy: frame-ancestors 'none'`` and ``X-Frame-Options: DENY``: no
  page may show the dashboard or an API answer in a frame (clickjacking: a hostile page
  laying the dashboard's STOP or move buttons under its own). The CSP directive is the
  standard; ``X-Frame-Options`` is for browsers that predate it. One exception: the
  campaign report (``/api/campaigns/{id}/report.{fmt}``), which the dashboard itself
  shows in a frame (``CampaignResult.tsx``), says ``frame-ancestors 'self'`` and
  ``SAMEORIGIN`` instead: framed by the dashboard's own origin only.
- ``X-Content-Type-Options: nosniff``: a browser takes each answer for the type it is
  declared as (a JSON body or a PNG is never run as a script or a style sheet).
- ``Referrer-Policy: no-referrer``: a link followed out of the dashboard does not tell
  the next site the lab server's address.

``SecurityHeaders`` is a pure ASGI middleware (it sees the response's start message
only, so streamed bodies and WebSockets pass untouched). A header a route set itself is
kept; the CSP is added beside a route's own policy (a browser enforces every policy it
receives, so a second one can only restrict). Installed outermost by
``backend.api.routes.dashboard.install``, it covers the Host check's 400 and the body
limit's 413 too; an unhandled exception's 500, written by Starlette's outermost error
middleware, has none of them (a bare error text, nothing to frame or sniff usefully).

The 3-D scene's port (``backend.services.live.scene``) sends the same ``nosniff`` and
``Referrer-Policy`` (``SCENE_HEADERS``), with a ``frame-ancestors`` naming the dashboard
instead of ``'none'``: the dashboard shows the scene in a frame.
"""

from __future__ import annotations

import re

from starlette.types import ASGIApp, Message, Receive, Scope, Send

SCENE_HEADERS: dict[str, str] = {
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}
"""The headers the main server and the scene's port both send."""
HEADERS: dict[str, str] = {
    "Content-Security-Policy": "frame-ancestors 'none'",
    "X-Frame-Options": "DENY",
    **SCENE_HEADERS,
}
"""Every answer of the main server carries these (but ``SAME_ORIGIN_FRAMES``)."""
SAME_ORIGIN_FRAME_HEADERS: dict[str, str] = {
    **HEADERS,
    "Content-Security-Policy": "frame-ancestors 'self'",
    "X-Frame-Options": "SAMEORIGIN",
}
"""What the answers the dashboard frames itself carry instead."""
SAME_ORIGIN_FRAMES = re.compile(r"/api/campaigns/[^/]+/report\.[a-z]+")
"""Paths the dashboard shows in a frame of its own page (the campaign report)."""
ALWAYS_ADDED = frozenset({"content-security-policy"})
"""Added even beside a route's own value (policies combine: the strictest wins)."""


def _raw(headers: dict[str, str]) -> tuple[tuple[bytes, bytes], ...]:
    return tuple((k.lower().encode("latin-1"), v.encode("latin-1")) for k, v in headers.items())


_RAW, _RAW_SAME_ORIGIN = _raw(HEADERS), _raw(SAME_ORIGIN_FRAME_HEADERS)
_RAW_ALWAYS = frozenset(name.encode("latin-1") for name in ALWAYS_ADDED)


class SecurityHeaders:
    """Add ``HEADERS`` to every HTTP response of ``app``."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        ours = _RAW_SAME_ORIGIN if SAME_ORIGIN_FRAMES.fullmatch(scope["path"]) else _RAW

        async def send_hardened(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", ()))
                present = {name.lower() for name, _ in headers}
                headers += [
                    (name, value)
                    for name, value in ours
                    if name in _RAW_ALWAYS or name not in present
                ]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_hardened)
