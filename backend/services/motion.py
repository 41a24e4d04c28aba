"""The motion system as the server uses it: soft limits, ownership and health in front of
the driver, for the motion routes and the campaign runner alike.

- **Soft limits**: a set-point, a jog's target or a profile is checked against the
  driver's axes before the driver sees it (``MotionLimitError`` names the axis and the
  limit; nothing moves then).
- **One command path**: every command (a person's move, jog or profile, a campaign's
  move or profile) runs its checks, its status read and its send under one command
  lock, and ``claim`` takes the same lock: a claim waits for a command already past its
  checks, and after the claim nothing but the owner can send. A person's command while
  a campaign owns the table is refused (``MotionConflictError`` naming the campaign).
- **STOP first, and latched**: STOP never takes the command lock. It latches at once
  (``stop_latched``), then stops the driver and tells the listeners (the campaign
  service pauses its campaign). While latched, every motion command is refused, the
  owning campaign's too, until a person releases it (``release_stop``: ``POST
  /api/motion/release`` or a campaign's resume). A command that was already past its
  checks when STOP came (its send reaches the driver after the stop) is stopped again
  at once, so nothing a concurrent client sent outlives a STOP. ``stop_in_lane`` runs
  the driver's stop on a thread pool of its own (``STOP_LANE``), never queued behind
  the web server's worker threads.
- **Health**: every failing command or status read marks the device degraded with the
  reason (``health``, shown by ``GET /api/health`` and ``GET /api/motion``); a status
  read that works marks it ok again.

Driver failures become ``MotionDeviceError``: its text is the driver's, ``detail`` the
sentence the API answers with.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime
from typing import NamedTuple, TypeVar

from backend.drivers.base import (
    AxisLimits,
    MotionDriver,
    MotionStatus,
    ProfileMotionDriver,
    profile_axis_problem,
    profile_problems,
    soft_limit_problems,
)
from backend.services.live.acquisition import DeviceHealth
from tofpose.lab.motion_profile import LimitProblem, MotionProfile, profile_from_spec

log = logging.getLogger(__name__)

T = TypeVar("T")

STOP_LANE = ThreadPoolExecutor(max_workers=2, thread_name_prefix="motion-stop")
"""The threads STOP's driver command runs on, and nothing else: exports, reports,
readers, the listeners and status reads cannot delay a STOP."""

STOP_AFTERMATH = ThreadPoolExecutor(max_workers=2, thread_name_prefix="motion-stop-after")
"""What follows a STOP: telling the listeners (the campaign service pauses its campaign)
and the status read STOP answers with; apart from ``STOP_LANE`` so that a listener
waiting on a lock or a controller that no longer answers its status never holds a
later STOP's driver command back."""


class MotionAbsentError(RuntimeError):
    """No motion system is configured."""


class MotionConflictError(RuntimeError):
    """Refused for now: another owner holds the motion system, it is moving, a profile
    runs, or it cannot do what is asked (no profile mode, no faults to reset)."""


class MotionLimitError(ValueError):
    """The request breaks the motion system's limits; ``problems`` names each (``field``
    empty where the whole set-point is meant, else the request field that sets it)."""

    def __init__(self, problems: list[LimitProblem]) -> None:
        super().__init__("; ".join(p.message for p in problems))
        self.problems = problems


class MotionDeviceError(RuntimeError):
    """The driver failed (``str``: its error); ``detail`` says what was refused."""

    def __init__(self, error: Exception, detail: str) -> None:
        super().__init__(str(error))
        self.detail = f"{detail}: {error}"


class MotionOwner(NamedTuple):
    """The campaign that holds the motion system while it runs."""

    campaign_id: int
    name: str


def _body_problems(messages: list[str]) -> list[LimitProblem]:
    return [LimitProblem("", m) for m in messages]


class MotionService:
    """One per app (``AppState.motion``); ``driver`` None when none is configured.
    Thread-safe."""

    def __init__(self, driver: MotionDriver | None, health: DeviceHealth | None = None) -> None:
        self.driver = driver
        self.health = health or DeviceHealth(state="ok")
        self._lock = threading.Lock()  # the fields below: held for no I/O
        self._commands = threading.RLock()  # one command at a time: check, read, send; claim
        self._owner: MotionOwner | None = None
        self._latched_at: datetime | None = None  # when a person's STOP latched, until released
        self.stops = 0  # how many times a person pressed STOP (campaigns.CampaignService)
        self._stop_listeners: list[Callable[[], None]] = []

    # -- what it is -------------------------------------------------------------------------
    @property
    def present(self) -> bool:
        return self.driver is not None

    @property
    def axes(self) -> dict[str, AxisLimits]:
        return self.driver.axes if self.driver is not None else {}

    def require(self) -> MotionDriver:
        if self.driver is None:
            raise MotionAbsentError("no motion system configured")
        return self.driver

    # -- ownership --------------------------------------------------------------------------
    @property
    def owner(self) -> MotionOwner | None:
        with self._lock:
            return self._owner

    def claim(self, campaign_id: int, name: str) -> None:
        """Campaign ``campaign_id`` holds the motion system until ``release``. Waits for a
        command already past its checks (the command lock), so that from the return on no
        one else's command reaches the driver."""
        with self._commands, self._lock:
            held = self._owner
            if held is not None and held.campaign_id != campaign_id:
                raise MotionConflictError(
                    f"campaign {held.campaign_id} ({held.name!r}) owns the motion system"
                )
            self._owner = MotionOwner(campaign_id, name)

    def release(self, campaign_id: int) -> None:
        with self._lock:
            if self._owner is not None and self._owner.campaign_id == campaign_id:
                self._owner = None

    # -- the STOP latch ------------------------------------------------------------------
    @property
    def stop_latched(self) -> bool:
        """Whether a person's STOP holds every motion command off (until ``release_stop``)."""
        with self._lock:
            return self._latched_at is not None

    @property
    def stop_latched_at(self) -> datetime | None:
        """When the STOP that holds the motion system was pressed (UTC), or None."""
        with self._lock:
            return self._latched_at

    def release_stop(self) -> bool:
        """A person lets motion commands through again; returns whether STOP was latched."""
        with self._lock:
            was = self._latched_at is not None
            self._latched_at = None
        if was:
            log.info("STOP released")
        return was

    def halted(self, campaign_id: int) -> bool:
        """Whether campaign ``campaign_id`` owns the motion system and STOP holds it."""
        with self._lock:
            owner = self._owner
            return (
                self._latched_at is not None
                and owner is not None
                and owner.campaign_id == campaign_id
            )

    def check_free(self) -> None:
        """``MotionConflictError`` while a campaign owns the motion system."""
        if (owner := self.owner) is not None:
            raise MotionConflictError(
                f"campaign {owner.campaign_id} ({owner.name!r}) owns the motion system while "
                "it runs: pause or cancel it first (STOP always works)"
            )

    def _check_latch(self) -> None:
        if (at := self.stop_latched_at) is not None:
            raise MotionConflictError(
                f"STOP was pressed at {at:%H:%M:%S} UTC and holds the motion system: release "
                "it first (POST /api/motion/release, or resume the campaign it paused)"
            )

    def _check_caller(self, by: int | None) -> None:
        """Under the command lock: STOP not latched; a person (``by`` None) needs the
        motion system free, campaign ``by`` must own it."""
        self._check_latch()
        if by is None:
            self.check_free()
        elif (owner := self.owner) is None or owner.campaign_id != by:
            raise MotionConflictError(f"campaign {by} does not own the motion system")

    def _send_unless_stopped(
        self,
        what: str,
        refused: str,
        command: Callable[[], object],
        driver: MotionDriver,
        stops_at_check: int,
    ) -> None:
        """Send ``command``; a STOP pressed since the checks (``stops_at_check``), whose
        stop the driver may have received before this command, is sent again after it."""
        self._send(what, refused, command)
        if self.stops != stops_at_check:
            log.warning("STOP came while a %s was on its way: stopping again", what)
            self._send("stop", "the motion system did not confirm the stop", driver.stop)
            raise MotionConflictError(
                f"STOP was pressed while the {what} was sent: the motion system was stopped again"
            )

    def on_stop(self, listener: Callable[[], None]) -> None:
        """Call ``listener`` whenever STOP is pressed (whether or not the driver confirms)."""
        self._stop_listeners.append(listener)

    # -- limits -----------------------------------------------------------------------------
    def limit_problems(self, setpoint: dict[str, float]) -> list[str]:
        """Unknown axes and values outside the soft limits (empty when acceptable)."""
        return soft_limit_problems(self.axes, setpoint)

    def profile_axis_problem(self, axis: str) -> LimitProblem | None:
        return profile_axis_problem(self.axes, axis)

    def profile_problems(self, axis: str, profile: MotionProfile) -> list[LimitProblem]:
        """Every limit ``profile`` (from its start) would break on ``axis``."""
        return profile_problems(self.axes, axis, profile)

    def profile_refusal(self) -> str | None:
        """Why this motion system cannot run motion profiles (the API's sentence), or None."""
        driver = self.require()
        if not callable(getattr(driver, "run_profile", None)):
            return f"the {driver.name!r} motion system cannot run motion profiles"
        return getattr(driver, "profile_unavailable", None)

    @property
    def profile_unavailable(self) -> str | None:
        """Why no profile can run, in a few words ("it has no profile mode"), or None."""
        driver = self.require()
        if not callable(getattr(driver, "run_profile", None)):
            return "it has no profile mode"
        return getattr(driver, "profile_unavailable", None)

    def profile_of(self, axis: str, spec: dict) -> MotionProfile:
        """The profile ``spec`` asks for on ``axis`` (a ramp's acceleration defaults to the
        axis' limit), not yet started anywhere."""
        return profile_from_spec(spec, self.axes[axis].max_accel)

    # -- reading ----------------------------------------------------------------------------
    def status(self) -> MotionStatus:
        """The status read now; a failure degrades ``health`` (``MotionDeviceError``)."""
        driver = self.require()
        try:
            st = driver.status()
        except Exception as exc:
            self.health.record_failure(f"motion status failed: {exc}")
            raise MotionDeviceError(exc, "cannot read the motion status") from exc
        self.health.record_ok()
        return st

    def status_at_rest(self, what: str, verb: str) -> MotionStatus:
        """The status read now: ``MotionDeviceError`` when it cannot be read (``what`` it
        was for), ``MotionConflictError`` while any axis moves (``verb`` once stopped)."""
        try:
            st = self.status()
        except MotionDeviceError as exc:
            raise MotionDeviceError(exc, f"cannot read {what}") from exc
        if st.busy:
            raise MotionConflictError(
                f"the motion system is still moving: {verb} once it has stopped"
            )
        return st

    # -- commands ---------------------------------------------------------------------------
    def _send(self, what: str, refused: str, command: Callable[[], object]) -> None:
        try:
            command()
        except Exception as exc:
            self.health.record_failure(f"{what} failed: {exc}")
            raise MotionDeviceError(exc, refused) from exc

    def move(self, setpoints: dict[str, float], *, by: int | None = None) -> None:
        """Start a move to ``setpoints`` ({axis: deg / mm}) for a person (``by`` None:
        refused while a campaign owns the motion system or a profile runs on one of the
        axes) or for campaign ``by`` (which must own it). Soft limits first."""
        driver = self.require()
        problems = self.limit_problems(setpoints)
        if problems:
            raise MotionLimitError(_body_problems(problems))
        with self._commands:
            stops = self.stops
            self._check_caller(by)
            if by is None:
                self._refuse_during_a_profile(driver, setpoints)
            self._send_unless_stopped(
                "move",
                "the motion system refused the move",
                lambda: driver.move_to(setpoints),
                driver,
                stops,
            )

    def _refuse_during_a_profile(self, driver: MotionDriver, setpoints: dict[str, float]) -> None:
        """A profile running on one of the axes to move. A status that cannot be read does
        not block the move (the driver refuses what it must)."""
        try:
            running = driver.status().profile
        except Exception:
            return
        if running is not None and running.axis in setpoints:
            raise MotionConflictError(
                f"a {running.kind} profile is running on {running.axis} "
                f"({running.remaining_s:.1f} s left): STOP it first"
            )

    def jog(self, axis: str, step: float) -> None:
        """Move ``axis`` by ``step`` from its encoder position read now (a person's jog:
        refused while anything moves or a campaign owns the motion system)."""
        driver = self.require()
        if axis not in driver.axes:
            raise MotionLimitError(
                _body_problems(
                    [f"this motion system has no {axis} axis (axes: {sorted(driver.axes)})"]
                )
            )
        with self._commands:
            stops = self.stops
            self._check_caller(None)
            st = self.status_at_rest(f"the {axis} position to jog from", "jog again")
            setpoint = {axis: st.positions[axis] + step}
            problems = self.limit_problems(setpoint)
            if problems:
                raise MotionLimitError(_body_problems(problems))
            self._send_unless_stopped(
                "move",
                "the motion system refused the move",
                lambda: driver.move_to(setpoint),
                driver,
                stops,
            )

    def start_profile(self, axis: str, spec: dict) -> MotionProfile:
        """A person's motion profile on ``axis`` from its encoder position read now
        (``spec`` as ``tofpose.lab.motion_profile.profile_from_spec`` takes it); returns it as
        started. Checks, in order: the axis, profile mode, ownership, at rest, limits."""
        if (problem := self.profile_axis_problem(axis)) is not None:
            raise MotionLimitError([problem])
        if (why := self.profile_refusal()) is not None:
            raise MotionConflictError(why)
        with self._commands:
            self._check_caller(None)
            st = self.status_at_rest(f"the {axis} position to start from", "start the profile")
            profile = self.profile_of(axis, spec).started_at(st.positions[axis])
            self.run_profile(axis, profile)
        return profile

    def run_profile(self, axis: str, profile: MotionProfile, *, by: int | None = None) -> None:
        """Run ``profile`` (already started at the axis' position) on ``axis``, for a
        person or for campaign ``by``; its limits are checked first."""
        driver = self.require()
        if not isinstance(driver, ProfileMotionDriver):
            raise MotionConflictError(
                f"the {driver.name!r} motion system cannot run motion profiles"
            )
        problems = self.profile_problems(axis, profile)
        if problems:
            raise MotionLimitError(problems)
        with self._commands:
            stops = self.stops
            self._check_caller(by)
            self._send_unless_stopped(
                "profile",
                "the motion system refused the profile",
                lambda: driver.run_profile(axis, profile),
                driver,
                stops,
            )

    def latch_stop(self) -> None:
        """The first half of a person's STOP, with no I/O: from now on every motion command
        is refused, and one already past its checks is stopped again after its send."""
        self.require()
        with self._lock:
            self.stops += 1
            if self._latched_at is None:
                self._latched_at = datetime.now(UTC)

    def stop(self, *, by: int | None = None) -> None:
        """Every axis stops where it is. Always accepted, never waits for another
        command. STOP pressed by a person (``by`` None) latches (``latch_stop``) and is
        told to the listeners, also when the driver does not confirm it; a campaign
        stopping its own motion (``by``) does neither."""
        driver = self.require()
        if by is None:  # before the command: nothing may move from now on
            self.latch_stop()
        try:
            self._send("stop", "the motion system did not confirm the stop", driver.stop)
        except MotionDeviceError:
            log.exception("stop failed")
            raise
        finally:
            if by is None:
                for listener in self._stop_listeners:
                    listener()

    async def stop_in_lane(self) -> None:
        """A person's STOP from the event loop: latched at once, then the driver's stop on
        ``STOP_LANE`` (never behind the web server's threads), then the listeners on
        ``STOP_AFTERMATH`` (not waited for: a listener that waits on a lock does not hold
        the answer or a later STOP back)."""
        self.latch_stop()
        loop = asyncio.get_running_loop()
        try:
            await loop.run_in_executor(STOP_LANE, self._stop_latched_driver)
        finally:
            STOP_AFTERMATH.submit(self._tell_listeners)

    def _stop_latched_driver(self) -> None:
        driver = self.require()
        try:
            self._send("stop", "the motion system did not confirm the stop", driver.stop)
        except MotionDeviceError:
            log.exception("stop failed")
            raise

    def _tell_listeners(self) -> None:
        for listener in self._stop_listeners:
            try:
                listener()
            except Exception:
                log.exception("a STOP listener failed")

    @staticmethod
    async def after_stop(work: Callable[[], T]) -> T:
        """Run ``work`` on ``STOP_AFTERMATH`` and wait for it (STOP's answer reads the
        status there)."""
        return await asyncio.get_running_loop().run_in_executor(STOP_AFTERMATH, work)

    def reset_faults(self) -> None:
        """Acknowledge the controller's axis faults (real rate tables; docs/devices.md): a
        person's command like a move, through the command path (refused while a campaign
        owns the table or a STOP is latched: clearing faults re-arms a halted table)."""
        driver = self.require()
        reset = getattr(driver, "reset_faults", None)
        if reset is None:
            raise MotionConflictError(f"the {driver.name!r} motion system has no faults to reset")
        with self._commands:
            self._check_caller(None)
            self._send("fault reset", "the motion system refused the fault reset", reset)
