"""GET / PUT /api/reference: which lab reference the live error is measured against
(backend/services/live/live_reference.py): the nominal lab geometry, or a stored calibration.
Campaign rows keep the nominal reference; reports apply a calibration with
``?calibration=ID``."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException

from backend.api.contract import errors
from backend.api.deps import ReadAuth, SessionDep, StateDep, WriteAuth
from backend.api.schemas.reference import ReferencePublic, ReferenceUpdate
from backend.services.calibrations import count_calibrations, get_calibration
from backend.services.live.live_reference import LiveReference
from backend.state import AppState

router = APIRouter(prefix="/api/reference", tags=["calibrations"])


def _public(state: AppState, session) -> ReferencePublic:
    ref = state.acquisition.reference
    return ReferencePublic(
        source="nominal" if ref.calibration_id is None else "calibration",
        label=ref.label,
        calibration_id=ref.calibration_id,
        n_calibrations=count_calibrations(session),
        calibrated_available=state.devices.world is not None,
    )


@router.get("", dependencies=[ReadAuth])
def get_reference(state: StateDep, session: SessionDep) -> ReferencePublic:
    """The live reference in use, and how many calibrations could be selected."""
    return _public(state, session)


@router.put("", dependencies=[WriteAuth], responses=errors(404))
def set_reference(body: ReferenceUpdate, state: StateDep, session: SessionDep) -> ReferencePublic:
    """Measure the live error against a stored calibration (``calibration_id``) or the
    nominal lab geometry (null). 404 for an unknown calibration (nothing changes)."""
    if body.calibration_id is None:
        state.acquisition.reference = LiveReference()
    else:
        row = get_calibration(session, body.calibration_id)
        if row is None:
            raise HTTPException(404, f"no calibration with id {body.calibration_id}")
        state.acquisition.reference = LiveReference.from_calibration(row)
    return _public(state, session)
