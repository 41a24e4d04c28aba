"""Three-axis turntable (outer yaw, middle pitch, inner roll) plus an optional rail.

Motion maths is separate from state: ``plan_move`` computes a rest-to-rest trapezoidal
(or triangular) velocity profile under rate and acceleration limits; after the profile a
decaying oscillation models settling. ``Turntable`` holds one plan per axis, checks soft
limits before accepting a set-point, and reports encoder readings quantised to the
encoder resolution with seeded noise. Time is explicit (``time_s`` arguments), so the
simulation can run faster than real time or in step with a clock.

An axis can also run a motion profile (tofpose.lab.motion_profile: a sine slew or a ramp),
accepted only when its peaks lie within the axis' soft, rate and acceleration limits; the
axis then follows it exactly (servo lag is not modelled, nor settling after it: a profile
ends at rest with a continuous rate), until it ends or ``stop``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tofpose.lab.motion_profile import MotionProfile

ROTARY_AXES = ("yaw", "pitch", "roll")  # outer, middle, inner
RAIL_AXIS = "rail"


@dataclass(frozen=True)
class AxisSpec:
    """Limits and encoder of one axis; rotary axes in degrees, the rail in mm."""

    name: str
    min_pos: float
    max_pos: float
    max_rate: float  # per second
    max_accel: float  # per second^2
    encoder_resolution: float
    encoder_noise: float  # 1-sigma
    settle_amplitude: float = 0.002  # overshoot as a fraction of the move
    settle_time_constant_s: float = 0.08
    settle_frequency_hz: float = 6.0
    settle_tolerance: float = 0.001  # settled when |overshoot| is below this

    @property
    def unit(self) -> str:
        return "mm" if self.name == RAIL_AXIS else "deg"


def default_axes() -> dict[str, AxisSpec]:
    """A lab rate table in the style of the paper's bench (§6.1) and a 15 m rail."""
    return {
        "yaw": AxisSpec("yaw", -170.0, 170.0, 20.0, 40.0, 1e-4, 2e-4),
        "pitch": AxisSpec("pitch", -60.0, 60.0, 20.0, 40.0, 1e-4, 2e-4),
        "roll": AxisSpec("roll", -180.0, 180.0, 30.0, 60.0, 1e-4, 2e-4),
        "rail": AxisSpec("rail", 0.0, 14700.0, 500.0, 250.0, 0.01, 0.02, settle_tolerance=0.05),
    }


@dataclass(frozen=True)
class MovePlan:
    """Rest-to-rest profile from ``start`` to ``end`` beginning at ``t0_s``."""

    start: float
    end: float
    t0_s: float
    rate: float  # peak rate reached
    accel: float
    t_acc_s: float
    t_flat_s: float

    @property
    def duration_s(self) -> float:
        return 2 * self.t_acc_s + self.t_flat_s

    def position(self, time_s: float) -> float:
        """Commanded position at a time (before settling dynamics)."""
        t = time_s - self.t0_s
        d = self.end - self.start
        if t <= 0 or d == 0:
            return self.start if t <= 0 else self.end
        sgn = np.sign(d)
        ta, tf, a, v = self.t_acc_s, self.t_flat_s, self.accel, self.rate
        if t < ta:
            s = 0.5 * a * t * t
        elif t < ta + tf:
            s = 0.5 * a * ta * ta + v * (t - ta)
        elif t < 2 * ta + tf:
            td = t - ta - tf
            s = 0.5 * a * ta * ta + v * tf + v * td - 0.5 * a * td * td
        else:
            return self.end
        return self.start + sgn * s


def plan_move(start: float, end: float, t0_s: float, max_rate: float, max_accel: float) -> MovePlan:
    """Trapezoidal profile; triangular when the move is too short to reach max_rate."""
    dist = abs(end - start)
    t_acc = max_rate / max_accel
    if max_accel * t_acc * t_acc >= dist:  # never reaches max_rate
        t_acc = float(np.sqrt(dist / max_accel))
        return MovePlan(start, end, t0_s, max_accel * t_acc, max_accel, t_acc, 0.0)
    t_flat = (dist - max_accel * t_acc * t_acc) / max_rate
    return MovePlan(start, end, t0_s, max_rate, max_accel, t_acc, t_flat)


@dataclass(frozen=True)
class ProfilePlan:
    """A motion profile run from ``t0_s``; reads like a ``MovePlan`` (start, end,
    duration, position at a time)."""

    profile: MotionProfile
    t0_s: float

    @property
    def start(self) -> float:
        return self.profile.start_deg

    @property
    def end(self) -> float:
        return self.profile.end_deg

    @property
    def duration_s(self) -> float:
        return self.profile.duration_s

    def position(self, time_s: float) -> float:
        return float(self.profile.angle_deg_at(time_s - self.t0_s))


class SoftLimitError(ValueError):
    """A set-point outside an axis' soft limits (or a profile beyond any axis limit)."""


class AxisBusyError(ValueError):
    """A command that needs the axis at rest, or not running a profile."""


@dataclass
class _AxisState:
    spec: AxisSpec
    plan: MovePlan | ProfilePlan
    stopped_at: float | None = None

    def running_profile(self, time_s: float) -> ProfilePlan | None:
        p = self.plan
        return p if isinstance(p, ProfilePlan) and time_s < p.t0_s + p.duration_s else None


@dataclass
class Turntable:
    """Simulated three-axis turntable with rail.

    Positions are dicts ``{"yaw": deg, "pitch": deg, "roll": deg, "rail": mm}``.
    """

    axes: dict[str, AxisSpec] = field(default_factory=default_axes)
    seed: int = 0

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._state = {
            name: _AxisState(spec, plan_move(0.0, 0.0, 0.0, spec.max_rate, spec.max_accel))
            for name, spec in self.axes.items()
        }

    def check_setpoints(self, setpoints: dict[str, float]) -> None:
        """Raise ``SoftLimitError``/``ValueError`` naming the offending axis."""
        for name, value in setpoints.items():
            if name not in self.axes:
                raise ValueError(f"unknown axis {name!r}; axes are {sorted(self.axes)}")
            spec = self.axes[name]
            if not np.isfinite(value):
                raise ValueError(f"{name} set-point must be a finite number, got {value}")
            if not spec.min_pos <= value <= spec.max_pos:
                raise SoftLimitError(
                    f"{name} set-point {value:g} {spec.unit} is outside the soft limits "
                    f"[{spec.min_pos:g}, {spec.max_pos:g}] {spec.unit}"
                )

    def move_to(self, setpoints: dict[str, float], time_s: float) -> float:
        """Start moving the named axes; returns the time all of them finish the profile.

        All set-points are checked before any axis moves; an axis running a profile
        takes no set-point (``AxisBusyError``: stop it first).
        """
        self.check_setpoints(setpoints)
        for name in setpoints:
            if self._state[name].running_profile(time_s) is not None:
                raise AxisBusyError(f"{name} is running a motion profile: stop it first")
        done = time_s
        for name, value in setpoints.items():
            st = self._state[name]
            here = self._commanded(name, time_s)
            st.plan = plan_move(here, float(value), time_s, st.spec.max_rate, st.spec.max_accel)
            done = max(done, time_s + st.plan.duration_s)
        for st in self._state.values():
            st.stopped_at = None
        return done

    def run_profile(self, name: str, profile: MotionProfile, time_s: float) -> MotionProfile:
        """Start ``profile`` on rotary axis ``name`` from where it stands; returns the
        profile as started (its ``start_deg`` set). The axis must be at rest (its move
        finished), and the profile within its soft, rate and acceleration limits
        (``SoftLimitError`` naming each one broken); nothing moves otherwise."""
        if name not in ROTARY_AXES or name not in self.axes:
            rotary = [a for a in ROTARY_AXES if a in self.axes]
            raise ValueError(f"profiles run on the rotary axes {rotary}, not {name!r}")
        st = self._state[name]
        if time_s < st.plan.t0_s + st.plan.duration_s:
            raise AxisBusyError(f"{name} is still moving: start the profile once it is at rest")
        started = profile.started_at(self._commanded(name, time_s))
        s = st.spec
        problems = started.limit_problems(name, s.min_pos, s.max_pos, s.max_rate, s.max_accel)
        if problems:
            raise SoftLimitError("; ".join(p.message for p in problems))
        st.plan = ProfilePlan(started, time_s)
        for other in self._state.values():
            other.stopped_at = None
        return started

    def running_profile(self, time_s: float) -> tuple[str, ProfilePlan] | None:
        """(axis, plan) of the profile running at ``time_s``, else None."""
        for name, st in self._state.items():
            if (plan := st.running_profile(time_s)) is not None:
                return name, plan
        return None

    def stop(self, time_s: float) -> None:
        """Stop every axis at once where it is (emergency stop)."""
        for name, st in self._state.items():
            here = self._commanded(name, time_s)
            st.plan = plan_move(here, here, time_s, st.spec.max_rate, st.spec.max_accel)
            st.stopped_at = time_s

    def _commanded(self, name: str, time_s: float) -> float:
        return self._state[name].plan.position(time_s)

    def _overshoot(self, name: str, time_s: float) -> float:
        st = self._state[name]
        t_end = st.plan.t0_s + st.plan.duration_s
        dt = time_s - t_end
        # a profile ends with rate and acceleration continuous: followed exactly, no ring
        if dt < 0 or st.plan.end == st.plan.start or isinstance(st.plan, ProfilePlan):
            return 0.0
        s = st.spec
        amp = s.settle_amplitude * (st.plan.end - st.plan.start)
        return float(
            amp
            * np.exp(-dt / s.settle_time_constant_s)
            * np.cos(2 * np.pi * s.settle_frequency_hz * dt)
        )

    def true_position(self, time_s: float) -> dict[str, float]:
        """Physical axis positions at a time (profile plus settling oscillation)."""
        return {n: self._commanded(n, time_s) + self._overshoot(n, time_s) for n in self.axes}

    def encoder_position(self, time_s: float) -> dict[str, float]:
        """Encoder readings: true position + noise, quantised to the resolution."""
        out = {}
        for n, p in self.true_position(time_s).items():
            s = self.axes[n]
            noisy = p + s.encoder_noise * self._rng.standard_normal()
            out[n] = float(np.round(noisy / s.encoder_resolution) * s.encoder_resolution)
        return out

    def is_stopped(self) -> bool:
        """True after ``stop`` until the next ``move_to``."""
        return any(st.stopped_at is not None for st in self._state.values())

    def target_position(self) -> dict[str, float]:
        return {n: st.plan.end for n, st in self._state.items()}

    def is_busy(self, time_s: float) -> bool:
        return any(time_s < st.plan.t0_s + st.plan.duration_s for st in self._state.values())

    def is_settled(self, time_s: float) -> bool:
        return not self.is_busy(time_s) and all(
            abs(self._overshoot(n, time_s)) <= self.axes[n].settle_tolerance for n in self.axes
        )

    def settle_time(self, time_s: float, step_s: float = 0.01) -> float:
        """Earliest time >= time_s at which all axes are settled."""
        t = max(time_s, max(st.plan.t0_s + st.plan.duration_s for st in self._state.values()))
        while not self.is_settled(t):
            t += step_s
        return t
