"""Turntable: GET /api/motion, POST /api/motion/move, POST /api/motion/jog,
POST /api/motion/profile, POST /api/motion/stop, POST /api/motion/release,
POST /api/motion/reset-faults.

The motion service (backend/services/motion.py) checks set-points against the driver's
soft limits before the driver sees them, and refuses a person's commands while a
campaign owns the motion system; the app answers its refusals (backend/app.py's service
errors: a limit 422 at the request field that sets it, a conflict 409, a device failure
503). A jog is relative to the axis' encoder position read when the request arrives, so
a client whose view is stale cannot jog from an old position. A profile
(tofpose.lab.motion_profile) is checked the same way, from the axis' encoder position,
against the soft, rate and acceleration limits. Stop is accepted from any authenticated
caller at any time, ends a running profile and latches: every motion command is refused
(409) until a person releases it. STOP is an async route whose driver command runs on a
thread pool of its own (``motion.STOP_LANE``): exports, reports and readers that fill
the web server's worker threads cannot delay it.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, status

from backend.api.contract import errors
from backend.api.deps import MotionDep, ReadAuth, StateDep, WriteAuth
from backend.api.presenters import motion_public
from backend.api.schemas.motion import JogRequest, MotionPublic, MoveRequest, ProfileRequest

router = APIRouter(prefix="/api/motion", tags=["motion"])
STARTS_MOTION: dict[str, Any] = {
    "status_code": status.HTTP_202_ACCEPTED,
    "dependencies": [WriteAuth],
    "responses": errors(409, 503),
}
"""Move, jog and profile: accepted at once (202), token, refused (409) or failed (503)."""


@router.get("", dependencies=[ReadAuth])
def get_motion(state: StateDep) -> MotionPublic:
    """Axes with soft limits, encoder positions (deg / mm), targets, busy/settled."""
    return motion_public(state)


@router.post("/move", **STARTS_MOTION)
def move_axes(body: MoveRequest, state: StateDep, motion: MotionDep) -> MotionPublic:
    """Start a move; returns at once (poll GET /api/motion for busy/settled).

    422 names every axis that is unknown to this motion system or outside its soft
    limits; in that case nothing is sent to the driver. 409 while a campaign owns the
    motion system or a profile runs on one of the axes (STOP ends it).
    """
    motion.move(body.axes())  # at least one axis: the schema's validator
    return motion_public(state)


@router.post("/jog", **STARTS_MOTION)
def jog_axis(body: JogRequest, state: StateDep, motion: MotionDep) -> MotionPublic:
    """Move one axis by the step given (deg / mm) from its encoder position now.

    409 while the motion system is still moving (any axis: a second click does not
    stack on a move in progress) or a campaign owns it; 422 when the axis is unknown or the
    target is outside the soft limits; 503 when the position cannot be read.
    """
    motion.jog(*body.axis_step())
    return motion_public(state)


@router.post("/profile", **STARTS_MOTION)
def run_profile(body: ProfileRequest, state: StateDep, motion: MotionDep) -> MotionPublic:
    """Run a motion profile (a sine slew or a constant-rate ramp) on one rotary axis from
    its encoder position when the request arrives; returns at once, and GET /api/motion
    shows the profile (kind, axis, elapsed and remaining seconds) while it runs. STOP
    ends it. Semantics of both kinds: docs/server.md, "Motion profiles".

    409 when this motion system cannot run profiles (a controller without synthesis
    mode), a campaign owns it, or it is moving; 422 naming each limit the profile would
    break from where the axis is (soft limits, rate limit, acceleration limit, by the
    request field that sets it), in which case nothing moves; 503 when the position
    cannot be read or the controller refuses.
    """
    motion.start_profile(body.axis, body.model_dump())
    return motion_public(state)


@router.post("/stop", dependencies=[WriteAuth], responses=errors(503))
async def stop_motion(state: StateDep, motion: MotionDep) -> MotionPublic:
    """Emergency stop: every axis stops where it is. Always accepted, also while a campaign
    runs (the campaign pauses, reason "STOP pressed"), and never queued behind other
    requests. STOP latches: every move, jog, profile and campaign start is refused (409)
    until a person releases it (POST /api/motion/release, or resuming the campaign)."""
    await motion.stop_in_lane()
    return await motion.after_stop(lambda: motion_public(state))


@router.post("/release", dependencies=[WriteAuth])
def release_stop(state: StateDep, motion: MotionDep) -> MotionPublic:
    """Release a latched STOP: motion commands are accepted again (a campaign that STOP
    paused stays paused until resumed). Accepted when nothing is latched too (no change)."""
    motion.release_stop()
    return motion_public(state)


@router.post("/reset-faults", dependencies=[WriteAuth], responses=errors(409, 503))
def reset_faults(state: StateDep, motion: MotionDep) -> MotionPublic:
    """Acknowledge the controller's axis faults once their cause is fixed (real rate
    tables; docs/devices.md). Interlocks stay open until the next move closes them. 409
    when this motion system has no faults to acknowledge (the simulator)."""
    motion.reset_faults()
    return motion_public(state)
