"""The OpenAPI contract, set once for all routes: readable operation ids, every error
status an operation can return (with one shared error body), and per-operation security.

Routes declare only what is specific to them (``responses=errors(404, 409)``); what
follows from the server's own machinery is added to every operation here:

- 401 (with ``WWW-Authenticate: Bearer``) on every operation that takes the token;
- 403 on every operation that needs more than the ``read`` scope: every state change
  (``operate``) and every operation of the ``admin`` tag (``admin``: keys and the audit
  trail, whose reads need the key even on loopback);
- 400 and 413 on every operation with a request body (body not parsable, body over
  ``TOFPOSE_MAX_BODY_BYTES``), 413 on every POST/PUT (the limit reads any body);
- 400 on every operation for a ``Host`` header the server does not serve (plain text:
  Starlette's TrustedHostMiddleware answers it);
- security: state changes need the bearer token; reads accept no token or the token
  (``[{}, {"HTTPBearer": []}]``: open when the server is bound to loopback, token
  otherwise, see docs/server.md); ``/api/health`` is open.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from fastapi.routing import APIRoute
from pydantic import BaseModel

BEARER = "HTTPBearer"
OPEN_OPERATIONS = {"getHealth"}
ADMIN_TAG = "admin"  # backend/api/routes/audit.py: every operation needs the admin scope


class ErrorPublic(BaseModel):
    """Every 4xx/5xx answer except 422: a sentence that names what is wrong."""

    detail: str


ERROR_DESCRIPTIONS = {
    400: "The body could not be parsed, or the Host header names a host this server does not serve",
    401: "No API token, or a wrong one (send 'Authorization: Bearer <token>')",
    403: "The API key's scope is below what the operation needs (operate: state changes; "
    "admin: keys, the audit trail)",
    404: "No such resource",
    409: "Conflicts with stored state (a name already taken, or the resource is busy)",
    413: "The request body is larger than the server's limit",
    503: "The device is absent or refused the command",
    504: "The device did not answer in time",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for route-specific error codes, with the shared body."""
    return {c: {"model": ErrorPublic, "description": ERROR_DESCRIPTIONS[c]} for c in codes}


def operation_id(route: APIRoute) -> str:
    """``list_catalogs`` -> ``listCatalogs``: the route function's name in camelCase."""
    head, *rest = route.name.split("_")
    return head + "".join(w.capitalize() for w in rest)


def _error_ref(code: int) -> dict[str, Any]:
    return {
        "description": ERROR_DESCRIPTIONS[code],
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorPublic"}}},
    }


def _complete_operation(method: str, op: dict[str, Any]) -> None:
    responses = op.setdefault("responses", {})
    takes_token = any(BEARER in req for req in op.get("security", []))
    admin = ADMIN_TAG in op.get("tags", [])
    is_read = method == "get" and not admin  # admin reads need the key, even on loopback
    if op.get("operationId") in OPEN_OPERATIONS:
        op["security"] = [{}]
    elif takes_token:
        op["security"] = [{}, {BEARER: []}] if is_read else [{BEARER: []}]
        if not is_read:
            responses.setdefault("403", _error_ref(403))
        r401 = _error_ref(401)
        if is_read:
            r401["description"] += " (only when the server is not bound to loopback)"
        r401["headers"] = {
            "WWW-Authenticate": {"description": "Bearer", "schema": {"type": "string"}}
        }
        responses.setdefault("401", r401)
    r400 = _error_ref(400)
    r400["content"]["text/plain"] = {"schema": {"type": "string"}}
    responses.setdefault("400", r400)
    if "requestBody" in op or method in ("post", "put", "patch"):
        responses.setdefault("413", _error_ref(413))


def apply_soft_limits(doc: dict[str, Any], limits: dict[str, tuple[float, float]]) -> None:
    """Write the motion system's soft limits into ``MoveRequest`` as minimum/maximum, so
    that the document says which set-points this server accepts (``limits`` by field
    name, e.g. ``{"yaw_deg": (-170, 170)}``)."""
    props = doc["components"]["schemas"].get("MoveRequest", {}).get("properties", {})
    for field, (lo, hi) in limits.items():
        if field in props:
            props[field].update(minimum=lo, maximum=hi)
            props[field]["description"] = (
                f"soft limits of this server's motion system: [{lo:.15g}, {hi:.15g}]"
            )


def complete_openapi(
    app: FastAPI, soft_limits: dict[str, tuple[float, float]] | None = None
) -> dict[str, Any]:
    """The app's OpenAPI document with the contract above applied. Cached on the app once
    the devices are known (``soft_limits`` given)."""
    if app.openapi_schema:
        return app.openapi_schema
    doc = get_openapi(
        title=app.title,
        version=app.version,
        summary=app.summary,
        description=app.description,
        routes=app.routes,
    )
    schemas = doc.setdefault("components", {}).setdefault("schemas", {})
    schemas.setdefault("ErrorPublic", ErrorPublic.model_json_schema())
    for path_item in doc.get("paths", {}).values():
        for method, op in path_item.items():
            if method in ("get", "put", "post", "delete", "patch"):
                _complete_operation(method, op)
    if soft_limits is not None:
        apply_soft_limits(doc, soft_limits)
        app.openapi_schema = doc
    return doc
