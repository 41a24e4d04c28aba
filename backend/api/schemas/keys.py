"""API keys (GET, POST /api/keys, DELETE /api/keys/{name})."""

from __future__ import annotations

from datetime import datetime
from typing import Literal

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody

ScopeName = Literal["read", "operate", "admin"]


class KeyPublic(BaseModel):
    """An API key as the server knows it (never the key itself)."""

    name: str
    scope: ScopeName
    created_at: datetime | None
    revoked_at: datetime | None


class KeyCreate(StrictBody):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._@-]*$")
    scope: ScopeName


class KeyCreated(KeyPublic):
    key: str = Field(description="the key: shown this once, only its hash is stored")
