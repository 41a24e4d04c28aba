"""Administration (the ``admin`` scope): the audit trail (GET /api/audit) and the API keys
(GET, POST /api/keys, DELETE /api/keys/{name}). A key is shown once, in the answer that
creates it; the server keeps its SHA-256 only (backend/services/keys.py)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Query, Response, status

from backend.api.contract import ErrorPublic, errors
from backend.api.deps import AdminAuth, StateDep
from backend.api.presenters import as_utc
from backend.api.schemas.audit import AuditEntryPublic
from backend.api.schemas.keys import KeyCreate, KeyCreated, KeyPublic
from backend.services.audit import MAX_LIMIT, AuditRecord
from backend.services.keys import ApiKey

router = APIRouter(prefix="/api", tags=["admin"], dependencies=[AdminAuth])
ADMIN_ONLY: dict[int | str, dict[str, Any]] = {
    403: {"model": ErrorPublic, "description": "The API key's scope is below 'admin'"}
}
KeyNameParam = Annotated[str, Path(min_length=1, max_length=64)]


def _audit_public(r: AuditRecord) -> AuditEntryPublic:
    return AuditEntryPublic(
        id=r.id,
        at=as_utc(r.at),
        key_name=r.key_name,
        client=r.client,
        method=r.method,
        path=r.path,
        body=r.body,
        status=r.status,
    )


def _key_public(k: ApiKey) -> dict[str, Any]:
    return {
        "name": k.name,
        "scope": k.scope.label,
        "created_at": as_utc(k.created_at),
        "revoked_at": as_utc(k.revoked_at),
    }


@router.get("/audit", responses=ADMIN_ONLY)
def list_audit(
    state: StateDep,
    limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
    before_id: Annotated[int | None, Query(ge=1, le=2**63 - 1)] = None,
) -> list[AuditEntryPublic]:
    """The audit trail, newest first: every POST, PUT, PATCH and DELETE, answered or
    refused. Page back with ``before_id`` = the last id of the page before."""
    return [_audit_public(r) for r in state.audit.entries(limit, before_id)]


@router.get("/keys", responses=ADMIN_ONLY)
def list_keys(state: StateDep) -> list[KeyPublic]:
    """Every API key, active and revoked (revoked keys keep their names), oldest first."""
    return [KeyPublic(**_key_public(k)) for k in state.keys.list()]


@router.post("/keys", status_code=status.HTTP_201_CREATED, responses={**ADMIN_ONLY, **errors(409)})
def create_key(body: KeyCreate, state: StateDep, response: Response) -> KeyCreated:
    """Make a key of this scope; the answer holds the key, which is not shown again.
    409 when the name is taken (also by a revoked key)."""
    key = state.keys.create(body.name, body.scope)
    record = next(k for k in state.keys.list() if k.name == body.name)
    response.headers["Cache-Control"] = "no-store"  # the key itself: kept by no cache
    return KeyCreated(**_key_public(record), key=key)


@router.delete("/keys/{name}", responses={**ADMIN_ONLY, **errors(404)})
def revoke_key(name: KeyNameParam, state: StateDep) -> KeyPublic:
    """Revoke a key: it stops working at once (its row and name stay, for the audit
    trail). 404 when no active key has this name."""
    return KeyPublic(**_key_public(state.keys.revoke(name)))
