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
from backend.drivers.base import CameraLimits, CameraSettings
from backend.services.campaigns.camera_plan import camera_limits
from backend.services.store import save_device_settings
from backend.state import AppState

router = APIRouter(prefix="/api/camera", tags=["camera"])
APPLY_TIMEOUT_S = 5.0


def _locked(state: AppState) -> str | None:
    """Why no setting can be changed by hand now (a campaign runs), or None."""
    owner = state.campaigns.running
    if owner is None:
        return None
    return (
        f"campaign {owner[0]} ({owner[1]!r}) sets the camera per set-point while it runs: "
        "pause or cancel it to change the camera's settings by hand"
    )


def _frequency_held(state: AppState) -> str | None:
    """Why the modulation frequency cannot change now (recordings record), or None."""
    recording = state.recordings.running() if state.recordings is not None else []
    if not recording:
        return None
    names = ", ".join(f"{r.id} ({r.name!r})" for r in recording)
    which = f"recording {names} records" if len(recording) == 1 else f"recordings {names} record"
    return (
        f"{which} now, and a recording holds one camera model (/camera) with which all "
        "its frames are read (where their distances wrap, their noise): stop it before "
        "changing the modulation frequency"
    )


def _public(state: AppState, settings: CameraSettings) -> CameraSettingsPublic:
    return camera_settings_public(
        settings, locked=_locked(state), frequency_held=_frequency_held(state)
    )


@router.get("/settings", dependencies=[ReadAuth])
def get_camera_settings(state: StateDep) -> CameraSettingsPublic:
    """What the camera uses, and what holds its settings now (``locked``,
    ``frequency_held``: the reasons a change would be refused, or null)."""
    return _public(state, state.devices.camera.get_settings())


class _HeldError(Exception):
    """A change that something holds (``_locked``, ``_frequency_held``): a 409."""


def _nearest_frequency_mhz(limits: CameraLimits, mhz: float) -> float:
    """The frequency a camera of ``limits`` would take for ``mhz``: the nearest one it
    supports (``modulation_frequencies_mhz``; the TOFcam-660 rounds), else ``mhz``."""
    choices = limits.modulation_frequencies_mhz
    return min(choices, key=lambda c: abs(c - mhz)) if choices else mhz


def _checked_apply(state: AppState, fields: dict) -> CameraSettings | None:
    """On the acquisition thread, so that nothing changes the camera between the checks
    and the change (a campaign's start reads and applies its settings there too): the
    settings applied, or None when ``fields`` change nothing (nothing applied, nothing
    to persist); ``_HeldError`` when a campaign runs or a recording holds the frequency."""
    cam = state.devices.camera
    limits = camera_limits(cam)
    current = cam.get_settings()
    wanted = replace(current, **fields)
    # the frequency the camera would take (the TOFcam-660 rounds to its nearest)
    wanted = replace(
        wanted,
        modulation_frequency_mhz=_nearest_frequency_mhz(limits, wanted.modulation_frequency_mhz),
    )
    if wanted == current:
        return None
    if (locked := _locked(state)) is not None:
        raise _HeldError(locked)
    changes_frequency = wanted.modulation_frequency_mhz != current.modulation_frequency_mhz
    # a source whose settings cannot change refuses any change itself (a replay: 503)
    if changes_frequency and limits.settable and (held := _frequency_held(state)):
        raise _HeldError(held)
    return cam.apply_settings(wanted)


@router.put("/settings", dependencies=[WriteAuth], responses=errors(409, 503, 504))
async def update_camera_settings(
    body: CameraSettingsUpdate, state: StateDep
) -> CameraSettingsPublic:
    """Change some or all settings; returns what the camera actually uses (it may clamp).

    409 while a campaign runs (it sets the camera per set-point, and restores the
    camera's own settings at its end), and for a new modulation frequency while a
    recording records (a recording holds one camera model, with which every frame of it
    is read: stop it first). Nothing is changed on a 409; a body that changes nothing
    is answered with the settings as they are (neither applied nor stored again)."""
    fields = body.model_dump(exclude_none=True)
    fut = state.acquisition.submit(lambda: _checked_apply(state, fields))
    try:
        applied = await asyncio.wait_for(asyncio.wrap_future(fut), APPLY_TIMEOUT_S)
    except _HeldError as exc:
        raise HTTPException(409, str(exc)) from exc
    except TimeoutError as exc:
        raise HTTPException(504, "the camera did not apply the settings in time") from exc
    except Exception as exc:
        raise HTTPException(503, f"the camera refused the settings: {exc}") from exc
    if applied is None:
        return _public(state, state.devices.camera.get_settings())

    def persist() -> None:
        with state.sessions() as session:
            save_device_settings(session, "camera", asdict(applied))

    await asyncio.to_thread(persist)
    return _public(state, applied)
