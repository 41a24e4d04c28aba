"""GET /api/devices: camera, motion and pipeline state in one call."""

from __future__ import annotations

from fastapi import APIRouter

from backend.api.deps import ReadAuth, StateDep
from backend.api.presenters import camera_state, motion_public, pipeline_state
from backend.api.schemas.devices import CameraDevicePublic, DevicesPublic

router = APIRouter(prefix="/api", tags=["status"], dependencies=[ReadAuth])


@router.get("/devices")
def get_devices(state: StateDep) -> DevicesPublic:
    cam = state.devices.camera
    m = cam.model
    camera = CameraDevicePublic(
        **camera_state(state).model_dump(),
        width_px=m.width,
        height_px=m.height,
        fx_px=m.fx,
        fy_px=m.fy,
        cx_px=m.cx,
        cy_px=m.cy,
        frames_processed=state.acquisition.frames_processed,
        frame_rate_hz=state.acquisition.frame_rate_hz,
        catalog=state.acquisition.catalog_name,
    )
    return DevicesPublic(camera=camera, motion=motion_public(state), pipeline=pipeline_state(state))
