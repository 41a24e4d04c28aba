"""GET/PUT /api/camera/settings. Applied on the acquisition thread, persisted, and
re-applied at the next start."""

from __future__ import annotations

import asyncio
from dataclasses import asdict, replace

from fastapi import APIRouter, HTTPException

from backend.api.contract import errors
from backend.api.deps import ReadAuth, StateDep, WriteAuth
from backend.api.presenters import camera_settings_public
from backend.api.schemas.camera import CameraSettingsPublic, CameraSettingsUpdate
from backend.services.store import save_device_settings

router = APIRouter(prefix="/api/camera", tags=["camera"])
APPLY_TIMEOUT_S = 5.0


@router.get("/settings", dependencies=[ReadAuth])
def get_camera_settings(state: StateDep) -> CameraSettingsPublic:
    return camera_settings_public(state.devices.camera.get_settings())


@router.put("/settings", dependencies=[WriteAuth], responses=errors(503, 504))
async def update_camera_settings(
    body: CameraSettingsUpdate, state: StateDep
) -> CameraSettingsPublic:
    """Change some or all settings; returns what the camera actually uses (it may clamp)."""
    cam = state.devices.camera
    wanted = replace(cam.get_settings(), **body.model_dump(exclude_none=True))
    fut = state.acquisition.submit(lambda: cam.apply_settings(wanted))
    try:
        applied = await asyncio.wait_for(asyncio.wrap_future(fut), APPLY_TIMEOUT_S)
    except TimeoutError as exc:
        raise HTTPException(504, "the camera did not apply the settings in time") from exc
    except Exception as exc:
        raise HTTPException(503, f"the camera refused the settings: {exc}") from exc

    def persist() -> None:
        with state.sessions() as session:
            save_device_settings(session, "camera", asdict(applied))

    await asyncio.to_thread(persist)
    return camera_settings_public(applied)
