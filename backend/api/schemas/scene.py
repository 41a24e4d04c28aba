"""The viser 3-D scene (GET, PUT /api/scene)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody


class ScenePublic(BaseModel):
    """The viser 3-D scene served by this process on a port of its own."""

    running: bool
    port: int | None = Field(default=None, description="the scene's port on this server's host")
    paused: bool = False
    reason: str = Field(default="", description="why the scene does not run (empty when it does)")
    updates: int = Field(default=0, description="scene updates since start")
    last_frame_index: int | None = None


class SceneUpdate(StrictBody):
    paused: bool
