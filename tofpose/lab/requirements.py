"""Accuracy requirements per axis: the one home of their defaults.

The defaults are the paper's accuracy goals (Zhu et al. 2022, §6.4): 6 mm in x and y,
28.3 mm in z (along the boresight), 0.15 deg in pitch, yaw and roll. A campaign's
``requirements`` (``POST /api/campaigns``) and a study's (``tofpose.study.spec``) both
default to them, so that a verdict means the same thing for both.

Axes: position ``x_mm``, ``y_mm``, ``z_mm`` (the target's origin in the camera frame,
mm) and attitude ``pitch_deg``, ``yaw_deg``, ``roll_deg`` (the facing Euler angles of
docs/architecture.md §3, deg); an error on an axis is measured minus reference (or
truth) on that axis.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

#: the axes a requirement is set on, position first (mm), then attitude (deg)
REQUIREMENT_AXES = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")

#: the paper's accuracy goals (§6.4): the default requirement of every axis
PAPER_REQUIREMENTS: Mapping[str, float] = MappingProxyType(
    {
        "x_mm": 6.0,
        "y_mm": 6.0,
        "z_mm": 28.3,
        "pitch_deg": 0.15,
        "yaw_deg": 0.15,
        "roll_deg": 0.15,
    }
)

#: the largest requirement an axis may be given: 100 m, or half a turn
MAX_REQUIREMENT = {"mm": 1e5, "deg": 180.0}


def axis_unit(axis: str) -> str:
    """``"mm"`` or ``"deg"``: the unit in the axis' name (``pitch_deg`` -> ``deg``)."""
    return axis.rsplit("_", 1)[1]
