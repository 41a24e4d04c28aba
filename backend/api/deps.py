"""Dependencies shared by the routers (``Annotated`` aliases, as in the FastAPI template)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, HTTPException, Query, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from backend.services.audit import KEY_NAME_STATE
from backend.services.campaigns.campaign_states import CampaignState
from backend.services.keys import ApiKey, Scope
from backend.services.motion import MotionService
from backend.state import AppState
from tofpose.io.interop import McapProfile

bearer_scheme = HTTPBearer(
    auto_error=False,
    description="API key: the admin key printed at the first start (stored in "
    "data/api_token, or TOFPOSE_API_TOKEN), or one made with `tofpose keys create` / "
    "POST /api/keys, of scope read, operate or admin",
)


Location = Sequence[str | int]
"""Where a problem is in the request, as FastAPI's ``loc``: ``["body", "generator"]``."""


def unprocessable(loc: Location, messages: list[str]) -> HTTPException:
    """A 422 shaped like FastAPI's own validation errors (``detail`` = list of
    ``{loc, msg, type}``), so clients handle every 422 the same way."""
    return unprocessable_at([(loc, m) for m in messages])


def unprocessable_at(problems: Sequence[tuple[Location, str]]) -> HTTPException:
    """As ``unprocessable``, with a location of its own for each message."""
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, located(problems))


def located(problems: Sequence[tuple[Location, str]]) -> list[dict[str, Any]]:
    """A 422's ``detail``: each message at its location, as FastAPI's validation errors."""
    return [{"loc": loc, "msg": m, "type": "value_error"} for loc, m in problems]


async def get_state(request: Request) -> AppState:
    return request.app.state.tofpose


StateDep = Annotated[AppState, Depends(get_state)]
CredentialsDep = Annotated[HTTPAuthorizationCredentials | None, Depends(bearer_scheme)]


def get_session(state: StateDep) -> Iterator[Session]:
    with state.sessions() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]

#: ``?profile=`` of the MCAP downloads (docs/interop.md); 422 naming the allowed values
#: for any other
McapProfileQuery = Annotated[
    McapProfile,
    Query(
        description="foxglove: Foxglove's schemas, mm (Foxglove, Rerun, `tofpose import "
        "mcap`); ros2: ROS 2 messages (cdr, ros2msg), m and rad, REP 103 frame ids "
        "(ros2 bag, rosbags)"
    ),
]

# Every auth dependency is ``async`` and does no I/O (keys are checked against the key
# service's copy in memory): FastAPI runs sync dependencies on AnyIO's worker threads,
# which exports and reports can fill, and STOP must never wait for one.


def _authorize(
    request: Request, state: AppState, creds: HTTPAuthorizationCredentials | None, needed: Scope
) -> ApiKey:
    """The key of this request if it has at least ``needed``: 401 without a valid key,
    403 (naming the scope needed) for a valid key of a lower scope. The key's name goes
    to the audit trail (``KEY_NAME_STATE``)."""
    if creds is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            f"this request needs an API key (token) of scope {needed.label!r} or above: "
            "send 'Authorization: Bearer <key>'",
            headers={"WWW-Authenticate": "Bearer"},
        )
    key = state.keys.verify(creds.credentials)
    if key is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "invalid API key (or API token): unknown or revoked",
            headers={"WWW-Authenticate": "Bearer"},
        )
    setattr(request.state, KEY_NAME_STATE, key.name)
    if not key.allows(needed):
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            f"this request needs the {needed.label!r} scope; key {key.name!r} has "
            f"{key.scope.label!r}",
        )
    return key


async def require_operate(request: Request, state: StateDep, creds: CredentialsDep) -> None:
    """Every request that moves hardware or changes state goes through this."""
    _authorize(request, state, creds, Scope.OPERATE)


async def require_admin(request: Request, state: StateDep, creds: CredentialsDep) -> None:
    """Keys, the audit trail and deletions."""
    _authorize(request, state, creds, Scope.ADMIN)


async def require_read(request: Request, state: StateDep, creds: CredentialsDep) -> None:
    """Reads are open when the server is bound to loopback (or ``open_reads``); else they
    need a key of any scope."""
    if not state.settings.reads_are_open:
        _authorize(request, state, creds, Scope.READ)


async def require_motion(state: StateDep) -> MotionService:
    """The motion service, when a motion system is configured (else 503)."""
    if not state.motion.present:
        raise HTTPException(status.HTTP_503_SERVICE_UNAVAILABLE, "no motion system configured")
    return state.motion


ReadAuth = Depends(require_read)
WriteAuth = Depends(require_operate)  # the "operate" scope
AdminAuth = Depends(require_admin)
MotionDep = Annotated[MotionService, Depends(require_motion)]


def finished_recording(state: AppState, campaign_id: int, missing_status: int = 404) -> Path:
    """Campaign ``campaign_id``'s HDF5 recording: 404 for no such campaign,
    ``missing_status`` for one without a recording (404 where the recording is the
    resource asked for, a download; 409 where the campaign is, and its state does not
    allow the request), 409 while it is being written."""
    campaign = state.campaigns.repository.get(campaign_id)  # CampaignNotFoundError: 404
    path = state.campaigns.recording_path(campaign_id)
    if not campaign.record_raw or not path.exists():
        raise HTTPException(
            missing_status,
            f"campaign {campaign_id} has no raw recording"
            + ("" if campaign.record_raw else " (record_raw was off)"),
        )
    if campaign.status is CampaignState.RUNNING:
        raise HTTPException(
            409,
            f"campaign {campaign_id} is running and writing its "
            "recording: pause it or wait until it is done",
        )
    return path
