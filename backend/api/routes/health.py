"""GET /api/health."""

from __future__ import annotations

from fastapi import APIRouter
from sqlalchemy import text

import backend
from backend.api.deps import StateDep
from backend.api.schemas import DeviceStatePublic, HealthPublic
from backend.state import AppState

router = APIRouter(prefix="/api", tags=["status"])


def camera_state(state: AppState) -> DeviceStatePublic:
    h = state.acquisition.health
    return DeviceStatePublic(
        driver=state.devices.camera.name,
        state=h.state,
        last_error=h.last_error,
        error_count=h.error_count,
    )


def motion_state(state: AppState) -> DeviceStatePublic:
    if state.devices.motion is None:
        return DeviceStatePublic(driver="none", state="absent")
    h = state.motion_health
    return DeviceStatePublic(
        driver=state.devices.motion.name,
        state=h.state,
        last_error=h.last_error,
        error_count=h.error_count,
    )


@router.get("/health")
def health(state: StateDep) -> HealthPublic:
    """Always answers (no auth): overall status and the state of each device."""
    try:
        with state.engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        db = "ok"
    except Exception:
        db = "error"
    cam, mot = camera_state(state), motion_state(state)
    healthy = db == "ok" and cam.state in ("ok", "starting") and mot.state in ("ok", "absent")
    return HealthPublic(
        status="ok" if healthy else "degraded",
        version=backend.__version__,
        uptime_s=state.uptime_s,
        database=db,
        camera=cam,
        motion=mot,
    )
