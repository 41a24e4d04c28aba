"""The options a /ws/live client sends (docs/server.md, "WebSocket `/ws/live`")."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator

from backend.api.schemas.common import StrictBody


class LiveOptions(StrictBody):
    images: list[Literal["gray", "distance"]] = Field(default_factory=list, max_length=2)
    image_every: int = Field(default=5, ge=1, le=1000)
    image_step: int = Field(default=2, ge=1, le=8)
    raw: bool = False
    raw_credit: int = Field(default=2, ge=0, le=100)
    points: bool = False

    @field_validator("images")
    @classmethod
    def _each_kind_once(cls, kinds: list[str]) -> list[str]:
        return list(dict.fromkeys(kinds))  # ["gray", "gray"] sends gray once
