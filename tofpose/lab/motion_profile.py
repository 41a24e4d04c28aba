"""Motion profiles: one rotary axis' angle as a function of time (docs/server.md,
"Motion profiles").

Pure maths, shared by the simulated turntable (which follows a profile), the server's
check before anything moves (soft limits, rate and acceleration limits), the rate-table
emulator's synthesis mode, and dynamic campaigns and their reports (the reference angle,
rate and acceleration at any time).

Time ``t_s`` counts seconds from the profile's start. Before it the axis rests at
``start_deg``; after ``duration_s`` it rests at ``end_deg``. Both kinds start and end at
rest with a continuous rate, so a table whose rate and acceleration limits cover the
profile's peaks can follow it exactly:

- ``SineProfile``: ``angle(t) = start + amplitude * e(t) * sin(2 pi t / period)``, about
  the start position. The envelope ``e`` rises from 0 to 1 over the first period as a
  raised cosine, stays 1 for ``cycles`` periods and falls back to 0 over the last period,
  so rate and acceleration are 0 at both ends; ``duration = (cycles + 2) * period``. The
  peak rate is ``amplitude * 2 pi / period``; the fades raise the peak acceleration about
  5 % above ``amplitude * (2 pi / period)^2`` (computed from samples, not assumed).
- ``RampProfile``: the rate rises at ``accel`` to ``rate`` (signed), holds for ``hold_s``
  and falls back to 0 at ``accel``, so the axis travels ``rate * (hold + |rate| / accel)``
  from its start; ``duration = hold + 2 |rate| / accel``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import Field, dataclass, replace
from functools import cached_property
from typing import Any, ClassVar, NamedTuple, Self

import numpy as np

FADE_SAMPLES = 4001
"""Samples of the sine's fade-in period searched for its peak rate and acceleration."""


class LimitProblem(NamedTuple):
    """Why a profile cannot run on an axis: the request field it comes from and a
    sentence naming the limit."""

    field: str
    message: str


def _require_positive(name: str, value: float, or_zero: bool = False) -> None:
    """ValueError unless ``value`` is finite and > 0 (>= 0 with ``or_zero``)."""
    if not (math.isfinite(value) and (value > 0 or (or_zero and value == 0))):
        raise ValueError(f"{name} must be {'>=' if or_zero else '>'} 0, got {value}")


def _scalar_or_array(value: np.ndarray, like) -> float | np.ndarray:
    """A float for a scalar time, the array for an array of times."""
    return float(value) if np.ndim(like) == 0 else value


class _Profile(ABC):
    """What both kinds share: the end position, a restart, and the limit check. Each
    kind is a frozen dataclass that defines the abstract members below."""

    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]
    """Set by ``@dataclass`` on each kind (lets ``started_at`` use ``replace``)."""
    kind: ClassVar[str]
    start_deg: float
    limit_fields: ClassVar[tuple[str, str, str]]
    """The request fields that set the sweep, the peak rate and the peak acceleration."""
    rate_words: ClassVar[str]
    accel_words: ClassVar[str]
    """How the peak rate and acceleration follow from those fields, for messages."""

    @property
    @abstractmethod
    def duration_s(self) -> float:
        """Seconds from the start to the end at rest."""

    @property
    @abstractmethod
    def angle_range_deg(self) -> tuple[float, float]:
        """The lowest and highest angle swept, deg."""

    @property
    @abstractmethod
    def peak_rate_deg_s(self) -> float:
        """The largest |rate|, deg/s."""

    @property
    @abstractmethod
    def peak_accel_deg_s2(self) -> float:
        """The largest |acceleration|, deg/s^2."""

    @property
    @abstractmethod
    def _travel_words(self) -> str:
        """What sets the sweep, for the soft-limit message."""

    @abstractmethod
    def angle_deg_at(self, t_s: Any) -> float | np.ndarray:
        """Angle, deg, at ``t_s`` seconds from the start (scalar or array)."""

    @property
    def end_deg(self) -> float:
        return float(self.angle_deg_at(self.duration_s))

    def started_at(self, start_deg: float) -> Self:
        """The same profile run from ``start_deg``."""
        return replace(self, start_deg=float(start_deg))

    def limit_problems(
        self,
        axis: str,
        min_deg: float,
        max_deg: float,
        max_rate_deg_s: float,
        max_accel_deg_s2: float,
    ) -> list[LimitProblem]:
        """Every limit of ``axis`` this profile (run from its ``start_deg``) would break:
        soft limits, rate limit, acceleration limit (empty when it can run)."""
        lo, hi = self.angle_range_deg
        travel_field, rate_field, accel_field = self.limit_fields
        out: list[LimitProblem] = []
        if lo < min_deg or hi > max_deg:
            out.append(
                LimitProblem(
                    travel_field,
                    (
                        f"{axis} would sweep [{lo:.6g}, {hi:.6g}] deg "
                        f"from {self.start_deg:.6g} deg, "
                        f"beyond its soft limits [{min_deg:.6g}, {max_deg:.6g}] deg "
                        f"({self._travel_words})"
                    ),
                )
            )
        if self.peak_rate_deg_s > max_rate_deg_s:
            out.append(
                LimitProblem(
                    rate_field,
                    (
                        f"peak rate {self.peak_rate_deg_s:.6g} deg/s ({self.rate_words}) exceeds "
                        f"the {axis} rate limit of {max_rate_deg_s:.6g} deg/s"
                    ),
                )
            )
        if self.peak_accel_deg_s2 > max_accel_deg_s2:
            out.append(
                LimitProblem(
                    accel_field,
                    (
                        f"peak acceleration {self.peak_accel_deg_s2:.6g} deg/s^2 "
                        f"({self.accel_words}) exceeds the {axis} acceleration limit of "
                        f"{max_accel_deg_s2:.6g} deg/s^2"
                    ),
                )
            )
        return out


@dataclass(frozen=True)
class SineProfile(_Profile):
    """A sine slew about ``start_deg`` with raised-cosine fades (see module)."""

    amplitude_deg: float
    period_s: float
    cycles: int
    start_deg: float = 0.0

    kind: ClassVar[str] = "sine"
    limit_fields: ClassVar[tuple[str, str, str]] = ("amplitude_deg", "amplitude_deg", "period_s")
    rate_words: ClassVar[str] = "amplitude_deg x 2 pi / period_s"
    accel_words: ClassVar[str] = "about amplitude_deg x (2 pi / period_s)^2"

    def __post_init__(self) -> None:
        _require_positive("amplitude_deg", self.amplitude_deg)
        _require_positive("period_s", self.period_s)
        if int(self.cycles) != self.cycles or self.cycles < 1:
            raise ValueError(f"cycles must be a whole number >= 1, got {self.cycles}")

    @property
    def omega_rad_s(self) -> float:
        return 2.0 * math.pi / self.period_s

    @property
    def duration_s(self) -> float:
        return (self.cycles + 2) * self.period_s

    @property
    def angle_range_deg(self) -> tuple[float, float]:
        return self.start_deg - self.amplitude_deg, self.start_deg + self.amplitude_deg

    def _terms(self, t_s):
        """omega, the envelope e, e', e'' and sin, cos of omega t at times ``t_s``."""
        T, d = self.period_s, self.duration_s
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, d)
        k, w = math.pi / T, self.omega_rad_s
        x = np.minimum(np.minimum(t, d - t), T)  # time from the nearer end, at most T
        sign = np.where(t > d - T, -1.0, 1.0)  # the fade-out runs backwards in time
        e = 0.5 * (1.0 - np.cos(k * x))
        de = sign * 0.5 * k * np.sin(k * x)
        d2e = 0.5 * k * k * np.cos(k * x) * (x < T)  # e is constant between the fades
        return w, e, de, d2e, np.sin(w * t), np.cos(w * t)

    def angle_deg_at(self, t_s):
        """Angle, deg, at ``t_s`` seconds from the start (scalar or array)."""
        w, e, de, d2e, s, c = self._terms(t_s)
        return _scalar_or_array(self.start_deg + self.amplitude_deg * e * s, t_s)

    def rate_deg_s_at(self, t_s):
        """Rate, deg/s (0 at both ends: e = e' = sin = 0 there)."""
        w, e, de, d2e, s, c = self._terms(t_s)
        return _scalar_or_array(self.amplitude_deg * (de * s + e * w * c), t_s)

    def accel_deg_s2_at(self, t_s):
        """Acceleration, deg/s^2 (0 at both ends)."""
        w, e, de, d2e, s, c = self._terms(t_s)
        return _scalar_or_array(
            self.amplitude_deg * (d2e * s + 2 * de * w * c - e * w * w * s), t_s
        )

    @cached_property
    def _fade_peaks(self) -> tuple[float, float]:
        """Peak |rate| and |acceleration| of the fade-in (the fade-out mirrors it): the
        largest sample, refined on a grid 100 times finer around it."""
        t = np.linspace(0.0, self.period_s, FADE_SAMPLES)
        step = t[1]
        peaks = []
        for f in (self.rate_deg_s_at, self.accel_deg_s2_at):
            i = int(np.argmax(np.abs(f(t))))
            fine = np.linspace(max(t[i] - step, 0.0), t[i] + step, 201)
            peaks.append(float(np.abs(f(fine)).max()))
        return peaks[0], peaks[1]

    @property
    def peak_rate_deg_s(self) -> float:
        return max(self.amplitude_deg * self.omega_rad_s, self._fade_peaks[0])

    @property
    def peak_accel_deg_s2(self) -> float:
        return max(self.amplitude_deg * self.omega_rad_s**2, self._fade_peaks[1])

    @property
    def _travel_words(self) -> str:
        return f"amplitude_deg {self.amplitude_deg:.6g} either side"


@dataclass(frozen=True)
class RampProfile(_Profile):
    """A constant-rate slew from ``start_deg``, entered and left at ``accel_deg_s2``
    (see module)."""

    rate_deg_s: float
    hold_s: float
    accel_deg_s2: float
    start_deg: float = 0.0

    kind: ClassVar[str] = "ramp"
    limit_fields: ClassVar[tuple[str, str, str]] = ("hold_s", "rate_deg_s", "accel_deg_s2")
    rate_words: ClassVar[str] = "rate_deg_s"
    accel_words: ClassVar[str] = "accel_deg_s2"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_deg_s) and self.rate_deg_s != 0):
            raise ValueError(f"rate_deg_s must be finite and not 0, got {self.rate_deg_s}")
        _require_positive("hold_s", self.hold_s, or_zero=True)
        _require_positive("accel_deg_s2", self.accel_deg_s2)

    @property
    def ramp_s(self) -> float:
        """Time to reach the rate from rest (and to stop from it)."""
        return abs(self.rate_deg_s) / self.accel_deg_s2

    @property
    def duration_s(self) -> float:
        return self.hold_s + 2.0 * self.ramp_s

    @property
    def travel_deg(self) -> float:
        return self.rate_deg_s * (self.hold_s + self.ramp_s)

    @property
    def angle_range_deg(self) -> tuple[float, float]:
        ends = (self.start_deg, self.start_deg + self.travel_deg)
        return min(ends), max(ends)

    def _phases(self, t_s):
        """Time clipped to the profile, time left, the masks of speeding up and slowing
        down, and the signed acceleration."""
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, self.duration_s)
        a = math.copysign(self.accel_deg_s2, self.rate_deg_s)
        return t, self.duration_s - t, t < self.ramp_s, t > self.ramp_s + self.hold_s, a

    def angle_deg_at(self, t_s):
        """Angle, deg, at ``t_s`` seconds from the start (scalar or array)."""
        t, left, speeding, slowing, a = self._phases(t_s)
        s = np.where(
            speeding,
            0.5 * a * t * t,
            np.where(
                slowing,
                self.travel_deg - 0.5 * a * left * left,
                self.rate_deg_s * (t - 0.5 * self.ramp_s),
            ),
        )
        return _scalar_or_array(self.start_deg + s, t_s)

    def rate_deg_s_at(self, t_s):
        """Rate, deg/s."""
        t, left, speeding, slowing, a = self._phases(t_s)
        v = np.where(speeding, a * t, np.where(slowing, a * left, self.rate_deg_s))
        return _scalar_or_array(v, t_s)

    def accel_deg_s2_at(self, t_s):
        """Acceleration, deg/s^2 (0 before the start and after the end)."""
        t, left, speeding, slowing, a = self._phases(t_s)
        raw = np.asarray(t_s, dtype=float)
        inside = (raw > 0) & (raw < self.duration_s)
        acc = np.where(speeding, a, np.where(slowing, -a, 0.0)) * inside
        return _scalar_or_array(acc, t_s)

    @property
    def peak_rate_deg_s(self) -> float:
        return abs(self.rate_deg_s)

    @property
    def peak_accel_deg_s2(self) -> float:
        return self.accel_deg_s2

    @property
    def _travel_words(self) -> str:
        return (
            f"rate_deg_s {self.rate_deg_s:.6g} for hold_s {self.hold_s:.6g} plus "
            f"the ramps: {self.travel_deg:.6g} deg"
        )


MotionProfile = SineProfile | RampProfile
"""Either kind; ``kind`` says which."""


def profile_from_spec(spec: dict, default_accel_deg_s2: float | None = None) -> MotionProfile:
    """The profile a request or a stored campaign set-point describes: ``spec`` holds
    ``kind`` ("sine": ``amplitude_deg``, ``period_s``, ``cycles``; "ramp": ``rate_deg_s``,
    ``hold_s``, ``accel_deg_s2`` or None for ``default_accel_deg_s2``, the axis' limit);
    other keys (``axis``) are ignored. Starts at 0 deg (``started_at`` moves it)."""
    kind = spec.get("kind")
    if kind == "sine":
        return SineProfile(
            float(spec["amplitude_deg"]), float(spec["period_s"]), int(spec.get("cycles", 1))
        )
    if kind == "ramp":
        accel = spec.get("accel_deg_s2")
        accel = default_accel_deg_s2 if accel is None else accel
        if accel is None:
            raise ValueError("a ramp needs accel_deg_s2 (the axis reports no acceleration limit)")
        return RampProfile(float(spec["rate_deg_s"]), float(spec["hold_s"]), float(accel))
    raise ValueError(f"unknown profile kind {kind!r} (sine or ramp)")
