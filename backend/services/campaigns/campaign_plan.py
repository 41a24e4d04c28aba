"""Campaign set-point lists: the generators behind ``POST /api/campaigns`` and the
duration estimate shown before a campaign runs. Pure functions of numbers.

A set-point is a dict over the axes ``yaw``, ``pitch``, ``roll`` (deg) and ``rail`` (mm);
an axis that is absent stays where it is. The generators mirror the paper's tests:

- ``grid``: every combination of the given axis values (Fig. 14's many set-points);
- ``range_sweep``: the rail from one position to another in equal steps (error vs range);
- ``stability``: one hold, measured for many frames (§6.3, Tables 1-3, Figs. 8-10);
- ``attitude_steps``: one axis stepped through a list of angles (Figs. 11-13);
- ``calibration``: rotations about all three axes at two or more ranges, so that the
  camera mount and target placement are observable (hand-eye / robot-world problem);
- ``profile``: a dynamic campaign: at each start point (a grid, as ``grid``), a motion
  profile on one rotary axis between two rests (``profile_starts``; the runner measures
  every frame, docs/campaigns.md "Dynamic campaigns").
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

AXES = ("yaw", "pitch", "roll", "rail")
SetPoint = dict[str, float]


def _values(v: float | Sequence[float] | None) -> list[float | None]:
    if v is None:
        return [None]
    if isinstance(v, int | float):
        return [float(v)]
    return [float(x) for x in v]


def grid(
    *,
    yaw_deg: float | Sequence[float] | None = None,
    pitch_deg: float | Sequence[float] | None = None,
    roll_deg: float | Sequence[float] | None = None,
    rail_mm: float | Sequence[float] | None = None,
) -> list[SetPoint]:
    """Cartesian product of the axis values, yaw outermost (rail innermost)."""
    out = []
    for combo in itertools.product(
        _values(yaw_deg), _values(pitch_deg), _values(roll_deg), _values(rail_mm)
    ):
        out.append({a: v for a, v in zip(AXES, combo, strict=True) if v is not None})
    return out


def range_sweep(
    *, rail_start_mm: float, rail_stop_mm: float, points: int, **fixed_deg: float | None
) -> list[SetPoint]:
    """``points`` rail positions from start to stop (inclusive); rotary axes fixed."""
    if points < 2:
        raise ValueError(f"a range sweep needs at least 2 points, got {points}")
    rails = np.linspace(rail_start_mm, rail_stop_mm, points)
    base = _fixed(fixed_deg)
    return [{**base, "rail": float(r)} for r in rails]


def stability(**axes: float | None) -> list[SetPoint]:
    """One hold at the given axes (all frames measured there)."""
    return [_fixed(axes)]


def attitude_steps(
    *, axis: str, steps_deg: Sequence[float], **fixed: float | None
) -> list[SetPoint]:
    """One rotary ``axis`` through ``steps_deg``, the others (and the rail) fixed."""
    if axis not in ("yaw", "pitch", "roll"):
        raise ValueError(f"attitude steps need a rotary axis (yaw, pitch, roll), got {axis!r}")
    if not steps_deg:
        raise ValueError("attitude steps need at least one angle")
    base = _fixed(fixed)
    base.pop(axis, None)
    return [{**base, axis: float(a)} for a in steps_deg]


def calibration(*, rails_mm: Sequence[float], amplitude_deg: float = 8.0) -> list[SetPoint]:
    """A well-conditioned set for estimating the camera mount and target placement.

    At each rail position: the rest pose, +/- ``amplitude_deg`` about each rotary axis
    alone, and two combined tilts. Rotations about three independent axes make the
    mount rotation observable; two or more ranges separate the mount translation from
    the target placement along the line of sight.
    """
    if len(rails_mm) < 2:
        raise ValueError("a calibration needs at least 2 rail positions")
    a = float(amplitude_deg)
    attitudes = [
        (0.0, 0.0, 0.0),
        (a, 0.0, 0.0),
        (-a, 0.0, 0.0),
        (0.0, a, 0.0),
        (0.0, -a, 0.0),
        (0.0, 0.0, 2 * a),
        (0.0, 0.0, -2 * a),
        (a, a / 2, a),
        (-a, -a / 2, -a),
    ]
    return [
        {"yaw": y, "pitch": p, "roll": r, "rail": float(rail)}
        for rail in rails_mm
        for (y, p, r) in attitudes
    ]


def profile_starts(
    *,
    axis: str,
    yaw_deg: float | Sequence[float] | None = None,
    pitch_deg: float | Sequence[float] | None = None,
    roll_deg: float | Sequence[float] | None = None,
    rail_mm: float | Sequence[float] | None = None,
) -> list[SetPoint]:
    """Start points of a dynamic campaign: the grid of the axis values given, the
    profile's own ``axis`` at 0 deg where no value is given for it (so that every
    profile starts where its soft-limit check assumed)."""
    if axis not in ("yaw", "pitch", "roll"):
        raise ValueError(f"a profile runs on a rotary axis (yaw, pitch, roll), got {axis!r}")
    points = grid(yaw_deg=yaw_deg, pitch_deg=pitch_deg, roll_deg=roll_deg, rail_mm=rail_mm)
    return [{**sp, axis: sp.get(axis, 0.0)} for sp in points]


def _fixed(axes: dict[str, float | None]) -> SetPoint:
    """{"yaw_deg": 1, "rail_mm": None} -> {"yaw": 1.0}."""
    out = {}
    for key, v in axes.items():
        name = key.removesuffix("_deg").removesuffix("_mm")
        if name not in AXES:
            raise ValueError(f"unknown axis {key!r}")
        if v is not None:
            out[name] = float(v)
    return out


def estimate_duration_s(
    setpoints: Sequence[SetPoint],
    start: dict[str, float],
    max_rate: dict[str, float],
    *,
    settle_s: float,
    frames_per_point: int,
    frame_rate_hz: float,
    settle_overhead_s: float = 0.5,
    dynamic_s: Sequence[float | None] | None = None,
) -> float:
    """Rough wall time of a campaign: per set-point, the slowest axis's move at its peak
    rate plus a settling overhead, the settle wait, and the frames at the camera rate
    (or, at a dynamic set-point, ``dynamic_s``: its profile and the rests around it)."""
    here = dict(start)
    total = 0.0
    for k, sp in enumerate(setpoints):
        move = max(
            (abs(v - here.get(a, v)) / max_rate[a] for a, v in sp.items() if a in max_rate),
            default=0.0,
        )
        total += move + (settle_overhead_s if move > 0 else 0.0) + settle_s
        dynamic = dynamic_s[k] if dynamic_s is not None else None
        total += dynamic if dynamic is not None else frames_per_point / frame_rate_hz
        here.update(sp)
    return total
