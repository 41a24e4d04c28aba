"""A campaign's camera settings (docs/campaigns.md, "Camera settings and metadata"):
settings per set-point or a sweep over the set-point list, checked against the camera's
limits before anything is stored, and the camera's identity (model, serial, firmware)
read from the device where its driver reports it.

A setting is a dict with ``integration_time_us`` and/or ``modulation_frequency_mhz``. A
sweep ``{"integration_time_us": [250, 500], "modulation_frequency_mhz": [6, 12]}``
measures every set-point at every combination of its lists, the set-point outermost (the
table stands still while the camera changes; the lists in the order given, integration
time outermost).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

from backend.drivers.base import CameraLimits

SETTING_FIELDS = ("integration_time_us", "modulation_frequency_mhz")
IDENTITY_FIELDS = ("camera_model", "camera_serial", "camera_firmware")
DEFAULT_LIMITS = CameraLimits(integration_time_us=(1.0, 20000.0))
"""For a camera whose driver does not say: the API's own bounds."""

Location = list[str | int]
Located = tuple[Location, str]
"""(where in the request, what is wrong), as a 422 lists it."""


def camera_limits(camera: Any) -> CameraLimits:
    """The camera's ``limits()`` (``CameraLimits``), or ``DEFAULT_LIMITS`` when its driver
    has none."""
    limits = getattr(camera, "limits", None)
    return limits() if callable(limits) else DEFAULT_LIMITS


def _g(v: float) -> str:
    return f"{v:.15g}"


def setting_problems(
    setting: dict[str, float], limits: CameraLimits, camera_name: str, where: Location
) -> list[Located]:
    """(location, message) for every field of ``setting`` this camera cannot take; each
    message names the field, the value and the allowed range or values."""
    out: list[Located] = []
    if setting and not limits.settable:
        return [(where, f"the {camera_name!r} camera's settings cannot be changed")]
    t = setting.get("integration_time_us")
    if t is not None:
        lo, hi = limits.integration_time_us
        if not lo <= t <= hi:
            out.append(
                (
                    [*where, "integration_time_us"],
                    f"integration_time_us {_g(t)} us is outside the {camera_name!r} camera's "
                    f"range {_g(lo)} to {_g(hi)} us",
                )
            )
    f = setting.get("modulation_frequency_mhz")
    if f is not None:
        choices = limits.modulation_frequencies_mhz
        if choices is not None and not any(abs(f - c) < 1e-9 for c in choices):
            out.append(
                (
                    [*where, "modulation_frequency_mhz"],
                    f"modulation_frequency_mhz {_g(f)} MHz is not one the {camera_name!r} "
                    f"camera supports: {', '.join(_g(c) for c in choices)} MHz",
                )
            )
        elif choices is None and not (
            limits.modulation_range_mhz[0] <= f <= limits.modulation_range_mhz[1]
        ):
            lo, hi = limits.modulation_range_mhz
            out.append(
                (
                    [*where, "modulation_frequency_mhz"],
                    f"modulation_frequency_mhz {_g(f)} MHz is outside the {camera_name!r} "
                    f"camera's range {_g(lo)} to {_g(hi)} MHz",
                )
            )
    return out


def sweep_settings(sweep: Mapping[str, Sequence[float] | None]) -> list[dict[str, float]]:
    """Every combination of a sweep's lists, integration time outermost."""
    lists = [(k, list(sweep[k] or [])) for k in SETTING_FIELDS if sweep.get(k)]
    if not lists:
        return []
    keys = [k for k, _ in lists]
    return [
        dict(zip(keys, (float(v) for v in combo), strict=True))
        for combo in itertools.product(*(v for _, v in lists))
    ]


def with_sweep(
    setpoints: list[dict[str, float]], sweep: Mapping[str, Sequence[float] | None]
) -> tuple[list[dict[str, float]], list[dict[str, float]]]:
    """(set-points, their camera settings): each set-point repeated for every setting of
    the sweep, in turn."""
    settings = sweep_settings(sweep)
    points = [sp for sp in setpoints for _ in settings]
    cameras = [dict(s) for _ in setpoints for s in settings]
    return points, cameras


def raw_recording_problems(
    cameras: list[dict[str, float]], base: dict[str, Any] | None, record_raw: bool
) -> list[Located]:
    """With ``record_raw``: a problem when the set-points (``cameras``: each one's
    settings, over the campaign-wide ``base``) are measured at more than one modulation
    frequency, counting the camera's own wherever neither gives one. The raw recording is
    one file with one camera model (``/camera``), with which every frame of it is read
    (where its distances wrap, their noise): one frequency per recorded campaign."""
    if not record_raw:
        return []
    fallback = (base or {}).get("modulation_frequency_mhz")
    used = {c.get("modulation_frequency_mhz", fallback) for c in cameras}
    if len(used) <= 1:
        return []
    named = [_g(f) + " MHz" for f in sorted(float(f) for f in used if f is not None)]
    own = " and the camera's own where none is given" if None in used else ""
    return [
        (
            ["body", "record_raw"],
            f"record_raw keeps one recording, and a recording holds one camera model "
            f"(/camera) with which all its frames are read; these set-points are measured "
            f"at {', '.join(named)}{own}: give every set-point one "
            "modulation_frequency_mhz, or record each frequency in its own campaign",
        )
    ]


def camera_identity(
    described: dict[str, str], given: dict[str, str | None]
) -> tuple[dict[str, str], list[Located]]:
    """The camera's model, serial and firmware to store: what the device reports
    (``described``: its driver's ``describe()``, keys ``model``, ``serial``,
    ``firmware``), else what the request gives (``given``, keys ``camera_*``). A given
    value the device contradicts is a problem naming both."""
    out: dict[str, str] = {}
    problems: list[Located] = []
    for field in IDENTITY_FIELDS:
        device = (described.get(field.removeprefix("camera_")) or "").strip()
        typed = (given.get(field) or "").strip()
        if device and typed and typed != device:
            problems.append(
                (
                    ["body", field],
                    f"{field} {typed!r} was given, but the connected camera reports "
                    f"{device!r}: leave it out to take the device's",
                )
            )
        out[field] = device or typed
    return out, problems


def plan_cameras(
    setpoints: list[dict[str, float]],
    per_point: list[dict[str, float]] | None,
    sweep: dict[str, list[float]] | None,
    base: dict[str, Any] | None,
    limits: CameraLimits,
    camera_name: str,
) -> tuple[list[dict[str, float]], list[dict[str, float]], list[Located]]:
    """(set-points, each one's camera settings, problems) of a request: ``per_point``
    settings (one per set-point, {} for none) or a ``sweep`` (the set-points repeated,
    ``with_sweep``), never both; every setting, the sweep's values and the campaign-wide
    ``base`` (its ``camera``) checked against ``limits``."""
    cameras = per_point or [{} for _ in setpoints]
    problems: list[Located] = []
    if sweep and any(cameras):
        problems.append(
            (
                ["body", "camera_sweep"],
                "give camera settings per set-point ('camera' in a set-point) or a "
                "'camera_sweep', not both",
            )
        )
    base_setting = {k: float(v) for k, v in (base or {}).items() if k in SETTING_FIELDS}
    problems += setting_problems(base_setting, limits, camera_name, ["body", "camera"])
    for i, c in enumerate(cameras):
        problems += setting_problems(c, limits, camera_name, ["body", "setpoints", i, "camera"])
    if sweep:
        for field in SETTING_FIELDS:
            for k, v in enumerate(sweep.get(field) or []):
                for loc, msg in setting_problems(
                    {field: float(v)}, limits, camera_name, ["body", "camera_sweep"]
                ):
                    problems.append(([*loc, k] if loc[-1] == field else loc, msg))
        if not problems:
            setpoints, cameras = with_sweep(setpoints, sweep)
    return setpoints, cameras, problems[:20]
