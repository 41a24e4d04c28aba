"""Turntable: GET /api/motion, POST /api/motion/move, POST /api/motion/jog,
POST /api/motion/stop, POST /api/motion/reset-faults.

Set-points are checked against the driver's soft limits here, before the driver sees
them. A jog is relative to the axis' encoder position read here, when the request
arrives, so a client whose view is stale cannot jog from an old position. Stop is
accepted from any authenticated caller at any time.
"""

from __future__ import annotations

import logging

from fastapi import APIRouter, HTTPException, status

from backend.api.contract import errors
from backend.api.deps import MotionDep, ReadAuth, StateDep, WriteAuth, unprocessable
from backend.api.presenters import motion_public
from backend.api.schemas import JogRequest, MotionPublic, MoveRequest
from backend.drivers.base import MotionDriver, soft_limit_problems
from backend.state import AppState

log = logging.getLogger(__name__)
router = APIRouter(prefix="/api/motion", tags=["motion"])


@router.get("", dependencies=[ReadAuth])
def get_motion(state: StateDep) -> MotionPublic:
    """Axes with soft limits, encoder positions (deg / mm), targets, busy/settled."""
    return motion_public(state)


@router.post(
    "/move",
    status_code=status.HTTP_202_ACCEPTED,
    dependencies=[WriteAuth],
    responses=errors(409, 503),
)
def move_axes(body: MoveRequest, state: StateDep, motion: MotionDep) -> MotionPublic:
    """Start a move; returns at once (poll GET /api/motion for busy/settled).

    422 names every axis that is unknown to this motion system or outside its soft
    limits; in that case nothing is sent to the driver.
    """
    setpoints = body.axes()  # at least one axis: the schema's validator
    problems = soft_limit_problems(motion.axes, setpoints)
    if problems:
        raise unprocessable(["body"], problems)
    _refuse_while_a_campaign_owns_it(state)
    _send_move(state, motion, setpoints)
    return motion_public(state)


@router.post(
    "/jog",
    status_code=status.HTTP_202_ACCEPTED,
    dependencies=[WriteAuth],
    responses=errors(409, 503),
)
def jog_axis(body: JogRequest, state: StateDep, motion: MotionDep) -> MotionPublic:
    """Move one axis by the step given (deg / mm) from its encoder position now.

    409 while the motion system is still moving (any axis: a second click does not
    stack on a move in progress) or a campaign owns it; 422 when the axis is unknown or the
    target is outside the soft limits; 503 when the position cannot be read.
    """
    axis, step = body.axis_step()
    if axis not in motion.axes:
        raise unprocessable(
            ["body"], [f"this motion system has no {axis} axis (axes: {sorted(motion.axes)})"]
        )
    _refuse_while_a_campaign_owns_it(state)
    try:
        st = motion.status()
    except Exception as exc:
        state.motion_health.record_failure(f"motion status failed: {exc}")
        raise HTTPException(503, f"cannot read the {axis} position to jog from: {exc}") from exc
    if st.busy:
        raise HTTPException(409, "the motion system is still moving: jog again once it has stopped")
    setpoint = {axis: st.positions[axis] + step}
    problems = soft_limit_problems(motion.axes, setpoint)
    if problems:
        raise unprocessable(["body"], problems)
    _send_move(state, motion, setpoint)
    return motion_public(state)


def _refuse_while_a_campaign_owns_it(state: AppState) -> None:
    if (owner := state.campaigns.owner) is not None:
        raise HTTPException(
            409,
            f"campaign {owner[0]} ({owner[1]!r}) owns the motion system while it runs: pause "
            "or cancel it first (STOP always works)",
        )


def _send_move(state: AppState, motion: MotionDriver, setpoints: dict[str, float]) -> None:
    try:
        motion.move_to(setpoints)
    except Exception as exc:
        state.motion_health.record_failure(f"move failed: {exc}")
        raise HTTPException(503, f"the motion system refused the move: {exc}") from exc


@router.post("/stop", dependencies=[WriteAuth], responses=errors(503))
def stop_motion(state: StateDep, motion: MotionDep) -> MotionPublic:
    """Emergency stop: every axis stops where it is. Always accepted, also while a campaign
    runs (the campaign pauses, reason "STOP pressed")."""
    try:
        motion.stop()
    except Exception as exc:
        log.exception("stop failed")
        state.motion_health.record_failure(f"stop failed: {exc}")
        raise HTTPException(503, f"the motion system did not confirm the stop: {exc}") from exc
    finally:
        state.campaigns.stop_pressed()
    return motion_public(state)


@router.post("/reset-faults", dependencies=[WriteAuth], responses=errors(409, 503))
def reset_faults(state: StateDep, motion: MotionDep) -> MotionPublic:
    """Acknowledge the controller's axis faults once their cause is fixed (real rate
    tables; docs/devices.md). Interlocks stay open until the next move closes them. 409
    when this motion system has no faults to acknowledge (the simulator)."""
    reset = getattr(motion, "reset_faults", None)
    if reset is None:
        raise HTTPException(409, f"the {motion.name!r} motion system has no faults to reset")
    try:
        reset()
    except Exception as exc:
        state.motion_health.record_failure(f"fault reset failed: {exc}")
        raise HTTPException(503, f"the motion system refused the fault reset: {exc}") from exc
    return motion_public(state)
