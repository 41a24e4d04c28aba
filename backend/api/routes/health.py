"""GET /api/health."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter

import backend
from backend.api.deps import StateDep
from backend.api.presenters import camera_state, motion_state, pipeline_state
from backend.api.schemas.health import HealthPublic
from backend.services.store import database_answers

router = APIRouter(prefix="/api", tags=["status"])


@router.get("/health")
def get_health(state: StateDep) -> HealthPublic:
    """Always answers (no auth): overall status, the state of each device and of the
    pipeline (its compiled kernels, and which implementation gives the live poses:
    the reference one while the kernels compile)."""
    db: Literal["ok", "error"] = "ok" if database_answers(state.engine) else "error"
    cam, mot = camera_state(state), motion_state(state)
    healthy = db == "ok" and cam.state in ("ok", "starting") and mot.state in ("ok", "absent")
    return HealthPublic(
        status="ok" if healthy else "degraded",
        version=backend.__version__,
        uptime_s=state.uptime_s,
        database=db,
        camera=cam,
        motion=mot,
        pipeline=pipeline_state(state),
    )
