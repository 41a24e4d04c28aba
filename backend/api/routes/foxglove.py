"""GET /api/foxglove: where the live Foxglove WebSocket server is served (docs/interop.md)."""

from __future__ import annotations

from fastapi import APIRouter

from backend.api.deps import ReadAuth, StateDep
from backend.api.presenters import foxglove_public
from backend.api.schemas.foxglove import FoxglovePublic

router = APIRouter(prefix="/api", tags=["status"])


@router.get("/foxglove", dependencies=[ReadAuth])
def get_foxglove(state: StateDep) -> FoxglovePublic:
    """The live Foxglove server's URL (open it in the Foxglove app: "Open connection",
    Foxglove WebSocket) and what it has published; ``running`` is false with a
    ``reason`` when it is off (``--foxglove-port``) or could not start."""
    return foxglove_public(state)
