"""GET /api/pose/latest and /api/pose/history."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Query

from backend.api.contract import errors
from backend.api.deps import ReadAuth, StateDep
from backend.api.presenters import pose_public
from backend.api.schemas.pose import PosePublic

router = APIRouter(prefix="/api/pose", tags=["pose"], dependencies=[ReadAuth])


@router.get("/latest", responses=errors(404))
def get_latest_pose(state: StateDep) -> PosePublic:
    """The last result: ok/reason, pose (mm, deg, quaternion), matched reflectors with
    pixel centroids and 3-D points, residual, stage timings, frame time, the lab reference
    and the error against it when the source has one."""
    sample = state.acquisition.latest
    if sample is None:
        raise HTTPException(404, "no frame has been processed yet")
    return pose_public(sample)


@router.get("/history")
def get_pose_history(
    state: StateDep, n: Annotated[int, Query(ge=1, le=100_000)] = 100
) -> list[PosePublic]:
    """The last ``n`` results, oldest first (bounded by the server's history size)."""
    return [pose_public(s) for s in state.acquisition.history(n)]
