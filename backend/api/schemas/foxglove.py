"""The live Foxglove server (GET /api/foxglove)."""

from __future__ import annotations

from pydantic import BaseModel, Field


class FoxglovePublic(BaseModel):
    """The live Foxglove WebSocket server (``foxglove-sdk``) run by this process."""

    running: bool
    url: str | None = Field(default=None, description="ws:// address for the Foxglove app")
    port: int | None = None
    subprotocols: list[str] = Field(
        default_factory=list,
        description="WebSocket subprotocols served on the port: the SDK's foxglove.sdk.v1 "
        "and the open protocol's foxglove.websocket.v1",
    )
    reason: str = Field(default="", description="why it does not run (empty when it does)")
    published: int = Field(default=0, description="frames published to subscribed clients")
    dropped: int = Field(
        default=0,
        description="frames skipped because the publisher was still busy with one "
        "(the camera loop never waits for it)",
    )
