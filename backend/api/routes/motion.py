"""Turntable: GET /api/motion, POST /api/motion/move, POST /api/motion/jog,
POST /api/motion/profile, POST /api/motion/stop, POST /api/motion/reset-faults.

Set-points are checked against the driver's soft limits here, before the driver sees
them. A jog is relative to the axis' encoder position read here, when the request
arrives, so a client whose view is stale cannot jog from an old position. A profile
(tofpose.motion_profile) is checked the same way, from the axis' encoder position, against
the soft, rate and acceleration limits. Stop is accepted from any authenticated caller at
any time, and ends a running profile.
"""

from __future__ import annotations

import logging

from fastapi import APIRouter, HTTPException, status

from backend.api.contract import errors
from backend.api.deps import (
    MotionDep,
    ReadAuth,
    StateDep,
    WriteAuth,
    unprocessable,
    unprocessable_at,
)
from backend.api.presenters import motion_public
from backend.api.schemas import (
    JogRequest,
    MotionPublic,
    MoveRequest,
    ProfileRequest,
)
from backend.drivers.base import (
    AxisLimits,
    MotionDriver,
    MotionStatus,
    profile_axis_problem,
    profile_problems,
    soft_limit_problems,
)
from backend.state import AppState
from tofpose.motion_profile import MotionProfile, profile_from_spec

log = logging.getLogger(__name__)
router = APIRouter(prefix="/api/motion", tags=["motion"])
STARTS_MOTION = {"status_code": status.HTTP_202_ACCEPTED, "dependencies": [WriteAuth],
                 "responses": errors(409, 503)}  # fmt: skip
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
    setpoints = body.axes()  # at least one axis: the schema's validator
    problems = soft_limit_problems(motion.axes, setpoints)
    if problems:
        raise unprocessable(["body"], problems)
    _refuse_while_a_campaign_owns_it(state)
    _refuse_during_a_profile(motion, setpoints)
    _send_move(state, motion, setpoints)
    return motion_public(state)


@router.post("/jog", **STARTS_MOTION)
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
    st = _status_at_rest(state, motion, f"the {axis} position to jog from", "jog again")
    setpoint = {axis: st.positions[axis] + step}
    problems = soft_limit_problems(motion.axes, setpoint)
    if problems:
        raise unprocessable(["body"], problems)
    _send_move(state, motion, setpoint)
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
    if (problem := profile_axis_problem(motion.axes, body.axis)) is not None:
        raise unprocessable_at([(["body", problem.field], problem.message)])
    if not callable(getattr(motion, "run_profile", None)):
        raise HTTPException(409, f"the {motion.name!r} motion system cannot run motion profiles")
    if (why := getattr(motion, "profile_unavailable", None)) is not None:
        raise HTTPException(409, why)
    _refuse_while_a_campaign_owns_it(state)
    st = _status_at_rest(state, motion, f"the {body.axis} position to start from",
                         "start the profile")  # fmt: skip
    profile = _profile_of(body, motion.axes[body.axis]).started_at(st.positions[body.axis])
    problems = profile_problems(motion.axes, body.axis, profile)
    if problems:
        raise unprocessable_at([(["body", p.field], p.message) for p in problems])
    try:
        motion.run_profile(body.axis, profile)
    except Exception as exc:
        state.motion_health.record_failure(f"profile failed: {exc}")
        raise HTTPException(503, f"the motion system refused the profile: {exc}") from exc
    return motion_public(state)


def _profile_of(body: ProfileRequest, limits: AxisLimits) -> MotionProfile:
    """The profile a request asks for (a ramp's acceleration defaults to the axis'
    limit, which ``profile_axis_problem`` has made sure is known)."""
    return profile_from_spec(body.model_dump(), limits.max_accel)


def _status_at_rest(state: AppState, motion: MotionDriver, what: str, verb: str) -> MotionStatus:
    """The motion status, read now: 503 when it cannot be read (``what`` it was for),
    409 while any axis moves (``verb`` once it has stopped)."""
    try:
        st = motion.status()
    except Exception as exc:
        state.motion_health.record_failure(f"motion status failed: {exc}")
        raise HTTPException(503, f"cannot read {what}: {exc}") from exc
    if st.busy:
        raise HTTPException(409, f"the motion system is still moving: {verb} once it has stopped")
    return st


def _refuse_during_a_profile(motion: MotionDriver, setpoints: dict[str, float]) -> None:
    """409 when a profile runs on one of the axes to move. A status that cannot be read
    does not block the move (the driver refuses what it must)."""
    try:
        running = motion.status().profile
    except Exception:
        return
    if running is not None and running.axis in setpoints:
        raise HTTPException(
            409,
            f"a {running.kind} profile is running on {running.axis} ({running.remaining_s:.1f} s "
            "left): STOP it first",
        )


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
