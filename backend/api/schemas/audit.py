"""The audit trail (GET /api/audit)."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field


class AuditEntryPublic(BaseModel):
    """One state-changing request: when (UTC), by which key (null: none valid), from
    where, what, and the HTTP status answered."""

    id: int
    at: datetime
    key_name: str | None
    client: str = Field(description="the client's address")
    method: str
    path: str
    body: str = Field(
        description="the JSON body, at most ~300 characters, with every field "
        "whose name contains token, key, secret or password redacted"
    )
    status: int
