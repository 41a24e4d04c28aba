"""A campaign request, checked and planned before anything is stored (docs/campaigns.md,
"Creating a campaign"): the set-point list of a generator, the motion profile of a
dynamic campaign, every reason the plan cannot run on this motion system, and the
duration estimate shown with a campaign.
"""

from __future__ import annotations

from dataclasses import dataclass

from backend.drivers.base import soft_limit_problems
from backend.services.campaigns import campaign_plan
from backend.services.campaigns.campaign_repository import CampaignView
from backend.services.motion import MotionDeviceError, MotionService
from tofpose.lab.motion_profile import profile_from_spec

AXIS_FIELDS = ("yaw_deg", "pitch_deg", "roll_deg", "rail_mm")
MAX_LISTED = 20
"""Problems listed one by one before the list says "... (more)"."""

Located = tuple[list[str | int], str]
"""(where in the request, what is wrong), as a 422 lists it."""


def expand(generator: dict) -> list[dict[str, float]]:
    """The set-point list of a generator request (``ValueError`` naming what is wrong)."""
    g = dict(generator)
    kind = g.pop("kind")
    if kind == "grid":
        return campaign_plan.grid(**g)
    if kind == "range_sweep":
        return campaign_plan.range_sweep(**g)
    if kind == "stability":
        return campaign_plan.stability(**g)
    if kind == "attitude_steps":
        return campaign_plan.attitude_steps(**g)
    if kind == "profile":
        return campaign_plan.profile_starts(
            axis=g["profile"]["axis"], **{a: g[a] for a in AXIS_FIELDS}
        )
    return campaign_plan.calibration(**g)


def dynamic_spec(generator: dict | None, motion: MotionService) -> dict | None:
    """The motion profile (with ``rest_s``) every set-point of a dynamic campaign runs,
    as stored on its set-points (a ramp without an acceleration gets the axis' limit,
    stored as such); None for a static campaign."""
    if generator is None or generator["kind"] != "profile":
        return None
    spec = {k: v for k, v in generator["profile"].items() if v is not None}
    spec["rest_s"] = generator["rest_s"]
    limits = motion.axes.get(spec["axis"])
    if (
        "accel_deg_s2" not in spec
        and spec["kind"] == "ramp"
        and limits is not None
        and limits.max_accel is not None
    ):
        spec["accel_deg_s2"] = float(limits.max_accel)
    return spec


def plan_problems(
    setpoints: list[dict[str, float]],
    axes: dict | None,
    *,
    frames_per_point: int,
    max_setpoints: int,
    max_frames: int,
) -> list[str]:
    """Why a set-point list cannot run on this motion system (empty when it can): empty
    or too long, too many frames in all, unknown axes or values outside the soft limits
    (each named with its index)."""
    if not setpoints:
        return ["the campaign has no set-points: give a non-empty 'setpoints' or a generator"]
    problems = []
    if len(setpoints) > max_setpoints:
        problems.append(f"{len(setpoints)} set-points is more than the maximum {max_setpoints}")
    if len(setpoints) * frames_per_point > max_frames:
        problems.append(
            f"{len(setpoints)} set-points x {frames_per_point} frames is more than the "
            f"maximum {max_frames} frames per campaign"
        )
    if axes is None:
        if any(setpoints):
            problems.append("no motion system is configured: set-points cannot be reached")
        return problems
    for i, sp in enumerate(setpoints):
        problems += [f"set-point {i}: {p}" for p in soft_limit_problems(axes, sp)]
        if len(problems) > MAX_LISTED:
            problems.append("... (more)")
            break
    return problems


def profile_plan_problems(
    setpoints: list[dict[str, float]], spec: dict, motion: MotionService
) -> list[Located]:
    """(loc, message) for every reason the profile cannot run from a start point: no
    profile mode, the axis, its soft/rate/acceleration limits (by the request field)."""
    if not motion.present:
        return []  # plan_problems names the missing motion system
    where: list[str | int] = ["body", "generator", "profile"]
    if (why := motion.profile_refusal()) is not None:
        return [(where, why)]
    axis = spec["axis"]
    if (problem := motion.profile_axis_problem(axis)) is not None:
        return [([*where, problem.field], problem.message)]
    profile = motion.profile_of(axis, spec)
    out: list[Located] = []
    for i, sp in enumerate(setpoints):
        for p in motion.profile_problems(axis, profile.started_at(sp[axis])):
            out.append(([*where, p.field], f"start point {i}: {p.message}"))
        if len(out) > MAX_LISTED:
            break
    return out


@dataclass(frozen=True)
class Planning:
    """What a duration estimate needs from the devices, read once per request (a real
    motion controller answers each status query over the wire)."""

    start: dict[str, float]
    rates: dict[str, float]
    frame_rate_hz: float

    @classmethod
    def read(cls, motion: MotionService, frame_rate_hz: float) -> Planning:
        rates = {n: a.max_rate for n, a in motion.axes.items()}
        try:
            start = motion.status().positions if motion.present else {}
        except MotionDeviceError:
            start = {}
        return cls(start, rates, frame_rate_hz)

    def estimate_s(self, campaign: CampaignView) -> float:
        """Seconds the set-points not done yet take from where the axes are now."""
        pending = campaign.pending
        return campaign_plan.estimate_duration_s(
            [sp.axes for sp in pending],
            self.start,
            self.rates,
            settle_s=campaign.settle_s,
            frames_per_point=campaign.frames_per_point,
            frame_rate_hz=self.frame_rate_hz,
            dynamic_s=[_dynamic_s(sp.profile) for sp in pending],
        )


def _dynamic_s(spec: dict | None) -> float | None:
    """A dynamic set-point's profile and rests (s), None at a static one."""
    if not spec:
        return None
    accel = spec.get("accel_deg_s2") or 1.0e9  # a ramp at the axis' limit: ramps ignored
    return profile_from_spec(spec, accel).duration_s + 2 * float(spec.get("rest_s", 2.0))
