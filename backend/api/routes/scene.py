"""GET/PUT /api/scene: where the viser 3-D scene is served, and pausing it."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException

from backend.api.contract import errors
from backend.api.deps import ReadAuth, StateDep, WriteAuth
from backend.api.presenters import scene_public
from backend.api.schemas.scene import ScenePublic, SceneUpdate

router = APIRouter(prefix="/api", tags=["status"])


@router.get("/scene", dependencies=[ReadAuth])
def get_scene(state: StateDep) -> ScenePublic:
    """The 3-D scene's port (on this server's host) and state; ``running`` is false with
    a ``reason`` when it was switched off or could not start."""
    return scene_public(state)


@router.put("/scene", dependencies=[WriteAuth], responses=errors(409))
def update_scene(body: SceneUpdate, state: StateDep) -> ScenePublic:
    """Pause (freeze) or resume the 3-D scene; the pipeline keeps running either way."""
    if state.scene is None:
        raise HTTPException(409, f"the 3-D scene is not running: {state.scene_reason}")
    state.scene.set_paused(body.paused)
    return scene_public(state)
