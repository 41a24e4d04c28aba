"""Bench calibrations: estimate from a campaign, list. Applied to a report with
``GET /api/campaigns/{id}/report.{fmt}?calibration=ID`` (docs/campaigns.md)."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, status

from backend.api.contract import errors
from backend.api.deps import ReadAuth, SessionDep, StateDep, WriteAuth, unprocessable
from backend.api.presenters import calibration_public
from backend.api.schemas.calibrations import CalibrationCreate, CalibrationPublic
from backend.services.calibrations import calibrate_from_campaign, stored_calibrations
from backend.services.store import NameTakenError

router = APIRouter(prefix="/api/calibrations", tags=["calibrations"])


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteAuth],
    responses=errors(404, 409),
)
def create_calibration(
    body: CalibrationCreate, state: StateDep, session: SessionDep
) -> CalibrationPublic:
    """Fit the camera mount and the target placement to the campaign's set-points and
    store the result with its 1-sigma and residuals. 422 when the campaign cannot
    determine them (fewer than 3 usable set-points, rotations about fewer than 2 axes) or
    the lab's nominal geometry is unknown; nothing is stored then."""
    if not state.campaigns.repository.exists(body.campaign_id):
        raise HTTPException(404, f"no campaign with id {body.campaign_id}")
    world = state.devices.world
    if world is None:
        raise unprocessable(
            ["body"],
            [
                "the lab's nominal camera mount and target placement "
                "are unknown for these devices (only the simulated lab "
                "defines them today)"
            ],
        )
    geometry = world.bench.geometry
    try:
        row = calibrate_from_campaign(
            session, body.campaign_id, body.name, geometry.T_inner_camera, geometry.T_lab_target
        )
    except NameTakenError:
        raise  # 409 (backend/app.py, SERVICE_ERRORS), not the 422 of the other ValueErrors
    except ValueError as exc:
        raise unprocessable(
            ["body", "campaign_id"], [f"campaign {body.campaign_id}: {exc}"]
        ) from exc
    return calibration_public(row)


@router.get("", dependencies=[ReadAuth])
def list_calibrations(session: SessionDep) -> list[CalibrationPublic]:
    """Stored calibrations, newest first."""
    return [calibration_public(r) for r in stored_calibrations(session)]
