"""The motion service in front of the simulated turntable: soft limits before the driver,
who holds the table (a campaign or a person), and the device's health."""

from __future__ import annotations

import re
import threading
import time

import pytest

from backend.drivers.sim import SimMotion, make_sim_world
from backend.services.motion import (
    MotionAbsentError,
    MotionConflictError,
    MotionDeviceError,
    MotionLimitError,
    MotionService,
)
from tests.backend.conftest import SpyMotion, wait_for

SINE = {"axis": "yaw", "kind": "sine", "amplitude_deg": 2.0, "period_s": 2.0, "cycles": 1}


@pytest.fixture
def spy() -> SpyMotion:
    return SpyMotion(SimMotion(make_sim_world(time_scale=20.0)))


@pytest.fixture
def motion(spy) -> MotionService:
    return MotionService(spy)


def _settled(motion: MotionService) -> None:
    wait_for(lambda: (st := motion.status()).settled and not st.busy, 10.0, "the table to settle")


def test_a_setpoint_outside_the_soft_limits_names_the_axis_and_the_limit(motion, spy):
    yaw = motion.axes["yaw"]
    with pytest.raises(MotionLimitError) as info:
        motion.move({"yaw": yaw.max_pos + 1.0, "rail": 11000.0})
    (problem,) = info.value.problems
    assert problem.field == ""  # the set-point as a whole, not one request field
    assert problem.message == (
        f"yaw set-point {yaw.max_pos + 1.0:.15g} deg is outside the soft "
        f"limits [{yaw.min_pos:.15g}, {yaw.max_pos:.15g}] deg"
    )
    with pytest.raises(MotionLimitError, match="this motion system has no tilt axis"):
        motion.move({"tilt": 1.0})
    with pytest.raises(MotionLimitError, match="pitch set-point must be a finite number"):
        motion.move({"pitch": float("nan")})
    assert spy.calls == []  # nothing reached the driver


def test_a_jog_past_the_soft_limit_is_refused_from_where_the_axis_is(motion, spy):
    motion.move({"yaw": motion.axes["yaw"].max_pos - 0.5})
    _settled(motion)
    spy.calls.clear()
    with pytest.raises(MotionLimitError, match="yaw set-point .* is outside the soft limits"):
        motion.jog("yaw", 1.0)
    motion.jog("yaw", -1.0)
    ((name, target),) = spy.calls
    # from the encoder reading, which jitters by up to ~0.01 deg when settled (one full
    # run read 168.4985 for 168.5)
    assert name == "move_to" and target["yaw"] == pytest.approx(
        motion.axes["yaw"].max_pos - 1.5, abs=0.01
    )


def test_a_campaign_that_owns_the_table_keeps_everyone_else_off(motion, spy):
    motion.claim(7, "grid-1")
    assert motion.owner == (7, "grid-1")
    refused = re.escape(
        "campaign 7 ('grid-1') owns the motion system while it runs: pause or "
        "cancel it first (STOP always works)"
    )
    for attempt in (
        lambda: motion.move({"yaw": 1.0}),
        lambda: motion.jog("yaw", 1.0),
        lambda: motion.start_profile("yaw", SINE),
    ):
        with pytest.raises(MotionConflictError, match=refused):
            attempt()
    with pytest.raises(MotionConflictError, match="campaign 8 does not own the motion system"):
        motion.move({"yaw": 1.0}, by=8)
    with pytest.raises(MotionConflictError, match="campaign 7 .* owns the motion system"):
        motion.claim(8, "other")
    assert spy.calls == []
    motion.move({"yaw": 1.0}, by=7)  # the owner moves
    assert spy.calls == [("move_to", {"yaw": 1.0})]
    motion.release(8)  # not the owner: nothing changes
    assert motion.owner == (7, "grid-1")
    motion.release(7)
    assert motion.owner is None
    _settled(motion)
    motion.move({"yaw": 2.0})  # free again


def test_stop_is_always_accepted_and_only_a_persons_stop_is_told(motion, spy):
    pressed = []
    motion.on_stop(lambda: pressed.append(motion.owner))
    motion.claim(3, "long")
    motion.stop(by=3)  # the campaign stops its own profile: not STOP pressed
    assert pressed == []
    motion.stop()  # STOP while a campaign owns the table
    assert pressed == [(3, "long")]
    assert [name for name, _ in spy.calls] == ["stop", "stop"]


def test_a_stop_the_driver_does_not_confirm_still_pauses_and_degrades(motion, spy):
    pressed = []
    motion.on_stop(lambda: pressed.append(True))

    def broken() -> None:
        raise ConnectionError("controller unplugged")

    spy.stop = broken
    with pytest.raises(MotionDeviceError) as info:
        motion.stop()
    assert str(info.value) == "controller unplugged"
    assert info.value.detail == "the motion system did not confirm the stop: controller unplugged"
    assert pressed == [True]
    assert motion.health.state == "degraded"
    assert motion.health.last_error == "stop failed: controller unplugged"


def test_health_follows_what_the_driver_answers(motion, spy):
    inner = spy.status

    def dead():
        raise TimeoutError("no answer from the controller")

    spy.status = dead
    with pytest.raises(MotionDeviceError, match="^no answer from the controller$"):
        motion.status()
    assert (motion.health.state, motion.health.last_error) == (
        "degraded",
        "motion status failed: no answer from the controller",
    )
    with pytest.raises(MotionDeviceError) as info:
        motion.jog("yaw", 1.0)
    assert info.value.detail == (
        "cannot read the yaw position to jog from: no answer from the controller"
    )
    assert motion.health.error_count == 2
    spy.status = inner
    motion.status()
    assert motion.health.state == "ok" and motion.health.error_count == 2

    def refuse(setpoints):
        raise RuntimeError("interlock open")

    spy.move_to = refuse
    with pytest.raises(MotionDeviceError) as info:
        motion.move({"yaw": 1.0})
    assert info.value.detail == "the motion system refused the move: interlock open"
    assert motion.health.last_error == "move failed: interlock open"


def test_a_jog_while_the_table_moves_is_refused(motion):
    motion.move({"yaw": 20.0})
    with pytest.raises(MotionConflictError, match="still moving: jog again once it has stopped"):
        motion.jog("yaw", 1.0)


def test_profiles_are_checked_against_the_axis_and_its_limits(motion, spy):
    with pytest.raises(MotionLimitError) as info:
        motion.start_profile("rail", {**SINE, "axis": "rail"})
    assert [(p.field, p.message) for p in info.value.problems] == [
        ("axis", "profiles run on rotary axes; rail is in mm")
    ]
    with pytest.raises(MotionLimitError) as info:
        motion.start_profile("yaw", {**SINE, "amplitude_deg": 500.0})
    assert {p.field for p in info.value.problems} >= {"amplitude_deg"}
    assert spy.calls == []
    profile = motion.start_profile("yaw", SINE)
    assert [name for name, _ in spy.calls] == ["run_profile"]
    assert profile.start_deg == pytest.approx(0.0, abs=1e-2)
    with pytest.raises(MotionConflictError, match="a sine profile is running on yaw"):
        motion.move({"yaw": 1.0})  # a person's move waits for STOP or the end
    motion.move({"pitch": 1.0})  # another axis moves


def test_a_controller_without_profile_mode_is_a_conflict_naming_it(spy):
    class NoProfiles:
        name, axes = "plain", spy.axes

        def status(self):
            return spy.status()

    motion = MotionService(NoProfiles())
    assert motion.profile_unavailable == "it has no profile mode"
    with pytest.raises(
        MotionConflictError, match="^the 'plain' motion system cannot run motion profiles$"
    ):
        motion.start_profile("yaw", SINE)


def test_without_a_motion_system_every_command_says_so():
    motion = MotionService(None)
    assert not motion.present and motion.axes == {} and motion.owner is None
    for attempt in (
        lambda: motion.move({"yaw": 1.0}),
        motion.stop,
        motion.status,
        lambda: motion.jog("yaw", 1.0),
    ):
        with pytest.raises(MotionAbsentError, match="no motion system configured"):
            attempt()
    motion.claim(1, "static")  # a campaign without set-points still owns the queue's slot
    assert motion.owner == (1, "static")


def test_the_owner_is_read_consistently_while_campaigns_come_and_go(motion):
    seen = set()
    deadline = time.monotonic() + 0.2
    while time.monotonic() < deadline:
        motion.claim(1, "a")
        seen.add(motion.owner)
        motion.release(1)
        seen.add(motion.owner)
    assert seen == {(1, "a"), None}


def test_after_a_persons_stop_the_owning_campaign_may_not_move_until_released(motion, spy):
    """STOP takes the table from the campaign that owns it: its next move (and profile)
    is refused, so a runner between its check and its command cannot start the table
    again after STOP returned; once released the campaign may move again, and a
    campaign stopping its own motion does not halt itself."""
    motion.claim(7, "grid")
    motion.stop(by=7)  # the campaign stopping its own slew
    assert not motion.stop_latched
    motion.move({"yaw": 1.0}, by=7)
    stops = motion.stops
    motion.stop()  # a person's STOP
    assert motion.stops == stops + 1 and motion.halted(7) and motion.stop_latched
    with pytest.raises(MotionConflictError, match="STOP was pressed at .* holds the motion system"):
        motion.move({"yaw": 2.0}, by=7)
    profile = motion.profile_of("yaw", SINE).started_at(0.0)
    with pytest.raises(MotionConflictError, match="STOP was pressed"):
        motion.run_profile("yaw", profile, by=7)
    assert [c for c, _ in spy.calls].count("move_to") == 1  # only the move before STOP
    assert motion.release_stop() is True
    assert not motion.halted(7) and not motion.stop_latched
    motion.move({"yaw": 2.0}, by=7)
    assert spy.calls[-1] == ("move_to", {"yaw": 2.0})


def test_stop_latches_for_everyone_until_a_person_releases_it(motion, spy):
    """STOP is an emergency stop, not a pause: a person's move, jog and profile after it
    are refused until ``release_stop``; releasing twice is harmless."""
    motion.stop()
    spy.calls.clear()
    for attempt in (
        lambda: motion.move({"yaw": 1.0}),
        lambda: motion.jog("yaw", 1.0),
        lambda: motion.start_profile("yaw", SINE),
    ):
        with pytest.raises(MotionConflictError, match="release it first"):
            attempt()
    assert spy.calls == []
    assert motion.stop_latched_at is not None
    assert motion.release_stop() is True and motion.release_stop() is False
    motion.move({"yaw": 1.0})
    assert spy.calls == [("move_to", {"yaw": 1.0})]


class _SlowSend(SpyMotion):
    """A driver whose move takes ``delay_s`` to be sent (an SCPI round trip)."""

    def __init__(self, inner, delay_s: float) -> None:
        super().__init__(inner)
        self.delay_s = delay_s
        self.sending = threading.Event()

    def move_to(self, setpoints):
        self.sending.set()  # past every check, on its way to the controller
        time.sleep(self.delay_s)
        super().move_to(setpoints)


def test_a_move_in_flight_when_stop_is_pressed_is_stopped_again():
    """The move passed its checks before STOP and reaches the driver after the stop: the
    service stops the table again at once and tells the sender, so STOP has the last word."""
    spy = _SlowSend(SimMotion(make_sim_world(time_scale=20.0)), delay_s=0.1)
    motion = MotionService(spy)
    errors: list[Exception] = []

    def person() -> None:
        try:
            motion.move({"yaw": 30.0})
        except MotionConflictError as exc:
            errors.append(exc)

    t = threading.Thread(target=person)
    t.start()
    assert spy.sending.wait(2.0)
    motion.stop()
    t.join(5.0)
    names = [c for c, _ in spy.calls]
    assert names == ["stop", "move_to", "stop"]  # the move came after the stop: stopped again
    assert len(errors) == 1 and "STOP was pressed while the move was sent" in str(errors[0])
    assert motion.stop_latched


class _SlowStatus(SpyMotion):
    """A driver whose status read takes ``delay_s`` (an SCPI round trip) and that records,
    with each command, which thread sent it and who owned the table when it arrived."""

    def __init__(self, inner, motion_ref: list, delay_s: float) -> None:
        super().__init__(inner)
        self.delay_s = delay_s
        self.motion_ref = motion_ref
        self.arrivals: list[tuple[str, str, object]] = []

    def status(self):
        time.sleep(self.delay_s)
        return super().status()

    def move_to(self, setpoints):
        owner = self.motion_ref[0]._owner  # noqa: SLF001 - the truth at arrival, unlocked
        self.arrivals.append(("move_to", threading.current_thread().name, owner))
        super().move_to(setpoints)


def _race_round(motion: MotionService, round_: int) -> list[str]:
    """Two people (a jog and a move, again and again) against a campaign that claims the
    table, moves and holds it for 60 ms; returns the people's outcomes ("sent" /
    "refused"). The people pause 5 ms between tries so that the claim, which waits for
    a command in flight, is not starved by their stream."""
    barrier = threading.Barrier(3)
    done = threading.Event()
    outcome: list[str] = []

    def person(kind: str) -> None:
        barrier.wait()
        while not done.is_set():
            try:
                if kind == "jog":
                    motion.jog("yaw", 0.05)
                else:
                    motion.move({"yaw": 0.35 + 0.01 * round_, "pitch": 0.2})
                outcome.append("sent")
            except MotionConflictError:
                outcome.append("refused")
            time.sleep(0.005)

    def campaign() -> None:
        barrier.wait()
        try:
            time.sleep(0.005 * (round_ % 5))
            motion.claim(100 + round_, "race")
            motion.move({"yaw": 5.0}, by=100 + round_)
            time.sleep(0.06)
        finally:
            done.set()

    threads = [
        threading.Thread(target=person, args=("jog",), name=f"person-jog-{round_}"),
        threading.Thread(target=person, args=("move",), name=f"person-move-{round_}"),
        threading.Thread(target=campaign, name=f"campaign-{round_}"),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    motion.release(100 + round_)
    return outcome


def test_no_command_from_a_non_owner_reaches_the_driver_while_a_campaign_claims_it():
    """The race of the security review: two people jog and move while a campaign claims
    the table, with a 20 ms status read. Every command that reaches the driver while a
    campaign owns it comes from the campaign's own thread (25 rounds)."""
    ref: list = []
    spy = _SlowStatus(SimMotion(make_sim_world(time_scale=50.0)), ref, delay_s=0.02)
    motion = MotionService(spy)
    ref.append(motion)
    outcomes = [o for round_ in range(25) for o in _race_round(motion, round_)]
    by_non_owner = [
        (name, owner)
        for _, name, owner in spy.arrivals
        if owner is not None and not name.startswith("campaign-")
    ]
    assert by_non_owner == []
    assert "refused" in outcomes  # the race was real: people were refused while campaigns held it
    assert any(name.startswith("campaign-") for _, name, _ in spy.arrivals)


def test_a_fault_reset_goes_through_the_command_path(motion, spy):
    """Clearing the controller's faults re-arms a halted table: refused while a campaign
    owns it or a STOP is latched, like a move; accepted once released."""
    resets: list[str] = []
    spy.reset_faults = lambda: resets.append("reset")
    motion.claim(7, "grid")
    with pytest.raises(MotionConflictError, match="campaign 7 .* owns the motion system"):
        motion.reset_faults()
    motion.release(7)
    motion.stop()
    with pytest.raises(MotionConflictError, match="release it first"):
        motion.reset_faults()
    assert resets == []
    motion.release_stop()
    motion.reset_faults()
    assert resets == ["reset"]
