"""What a campaign report says, whatever its format (docs/campaigns.md, "Reports").

The HTML and the PDF report show the same sections in the same order, all built here from
the report dict of ``reports.build``: the summary, the verdict (requirement, measured
value and pass/fail per axis, and where the requirement comes from), the findings, the
whole-campaign statistics, the per-set-point table. Axes, units and statistics are
named as a reader names them (``x (mm)``, ``max |error|``, ``3 sigma``), never by their
identifiers in the code or the JSON.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from backend.services.reports.analysis import AXES, MAD_TO_SIGMA, SINGULAR_K
from tofpose.lab.requirements import PAPER_REQUIREMENTS as PAPER_REQUIREMENTS_DEFAULTS

AXIS_NAMES = {
    "x_mm": "x",
    "y_mm": "y",
    "z_mm": "z",
    "pitch_deg": "pitch",
    "yaw_deg": "yaw",
    "roll_deg": "roll",
}
AXIS_UNITS = {a: a.rsplit("_", 1)[1] for a in AXES}
AXIS_GROUPS = (("Translation", "mm", AXES[:3]), ("Attitude", "deg", AXES[3:]))

# The default of ``requirements`` in POST /api/campaigns and of a study's: the accuracy
# goals of the paper (their one home: ``tofpose.lab.requirements``).
PAPER_REQUIREMENTS = PAPER_REQUIREMENTS_DEFAULTS
PAPER = (
    'Zhu et al., "System Design for Pose Determination of Spacecraft Using Time-of-Flight '
    'Sensors" (Space: Science & Technology, 2022), section 6.4'
)

# Column key of analysis.AxisStats -> (header, carries the axis's unit).
STAT_HEADERS = {
    "n": ("frames used", False),
    "n_removed": ("removed outliers", False),
    "bias": ("bias (mean error)", True),
    "std": ("std (1 sigma)", True),
    "rms": ("RMS error", True),
    "max_abs": ("max |error|", True),
    "three_sigma": ("3 sigma", True),
    "predicted_sigma": ("predicted 1-sigma", True),
    "sigma_ratio": ("sigma ratio (measured / predicted)", False),
    "requirement": ("requirement", True),
    "passed": ("result", False),
}
MEASURED_HEADERS = {
    "average": ("average", True),
    "maximum": ("maximum", True),
    "minimum": ("minimum", True),
    "fluctuation": ("fluctuation (max - min)", True),
}
COMMANDED_AXES = (
    ("yaw", "setpoint_yaw_deg"),
    ("pitch", "setpoint_pitch_deg"),
    ("roll", "setpoint_roll_deg"),
    ("rail", "setpoint_rail_mm"),
)


@dataclass
class Table:
    """A table as text cells; ``status[(row, column)]`` marks cells pass (True) or fail."""

    header: list[str]
    rows: list[list[str]]
    status: dict[tuple[int, int], bool] = field(default_factory=dict)
    caption: str = ""

    def sliced(self, start: int, stop: int, caption: str | None = None) -> Table:
        """Rows ``start:stop`` with the same header (and their marks)."""
        status = {(r - start, c): v for (r, c), v in self.status.items() if start <= r < stop}
        cap = self.caption if caption is None else caption
        return Table(self.header, self.rows[start:stop], status, cap)


@dataclass
class AxisVerdict:
    """One axis of the verdict: the requirement against the worst set-point."""

    axis: str
    requirement: float
    max_abs: float  # largest |error| after outlier removal, over all set-points
    worst_setpoint: int | None
    n_within: int
    n_judged: int
    passed: bool | None

    @property
    def share(self) -> float:
        """max |error| / requirement (1.0 = exactly at the requirement)."""
        return self.max_abs / self.requirement if self.requirement > 0 else math.nan


# -- numbers ---------------------------------------------------------------------------------
def fmt(v, digits: int = 3) -> str:
    """A cell value: floats to ``digits`` significant digits, missing/NaN as ``-``,
    booleans as ``pass`` / ``FAIL``."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    if isinstance(v, float):
        return f"{v:.{digits}g}" if math.isfinite(v) else "-"
    return str(v)


def with_unit(v, axis: str) -> str:
    """``4.21 mm`` / ``0.0312 deg``; ``-`` when undefined."""
    s = fmt(_num(v))
    return s if s == "-" else f"{s} {AXIS_UNITS[axis]}"


def axis_label(axis: str) -> str:
    """``x (mm)``, ``pitch (deg)``."""
    return f"{AXIS_NAMES[axis]} ({AXIS_UNITS[axis]})"


def _num(v) -> float:
    return math.nan if v is None else float(v)


# -- summary and verdict ---------------------------------------------------------------------
def title(report: dict) -> str:
    c = report["campaign"]
    return f"Campaign {c['id']}: {c['name']}"


def reference_label(report: dict) -> str:
    """The reference the errors are taken against, in words."""
    cal = report.get("calibration")
    if cal:
        own = ""
        if "mount_sigma_deg" in cal:  # reports made before the sigmas were carried lack them
            own = (
                f"; the reference's own 1-sigma: camera mount {cal['mount_sigma_deg']:.3f} "
                f"deg / {cal['mount_sigma_mm']:.2f} mm, target placement "
                f"{cal['placement_sigma_deg']:.3f} deg / {cal['placement_sigma_mm']:.2f} mm, "
                "part of every error below"
            )
        return f"calibrated reference (encoders + calibration {cal['id']} '{cal['name']}'{own})"
    labels = {
        "lab": "lab reference (encoders + nominal geometry; uncalibrated: the errors include "
        "the bench's own camera-mount and target-placement errors, which a calibration "
        "campaign measures and ?calibration=ID / --calibration ID removes)",
        "truth": "truth (the pose the simulator rendered; simulator only)",
    }
    return labels.get(report["reference"], f"{report['reference']} reference")


def summary(report: dict) -> str:
    """One paragraph: what was measured, how, and against what."""
    c = report["campaign"]
    rate = report["success_rate"]
    when = ""
    if c.get("started_at"):
        when = f" Run from {_minute(c['started_at'])}"
        when += f" to {_minute(c['finished_at'])} UTC." if c.get("finished_at") else " UTC."
    dyn = report.get("dynamic")
    if dyn:  # a dynamic campaign: every frame of its rests and profiles, not a count
        moving = sum(s["n_in_motion"] for s in dyn["setpoints"].values())
        how = (
            f"each a motion profile between two rests, after a settling time of "
            f"{c['settle_s']:g} s; every frame kept, {moving} during the profiles; of "
            f"the {report['n_frames']} at rest {report['n_ok']} gave a pose "
            f"({_percent(rate)}), and the statistics below are theirs"
        )
    else:
        how = (
            f"{c['frames_per_point']} frames each after a settling time of "
            f"{c['settle_s']:g} s; {report['n_ok']} of {report['n_frames']} frames gave a "
            f"pose ({_percent(rate)})"
        )
    return (
        f"Status {c['status']}; target catalog {c['catalog']}; {c['n_done']} of "
        f"{c['n_setpoints']} set-points measured, {how}. Errors are measured minus the "
        f"{reference_label(report)}.{when}"
    )


def _minute(iso: str) -> str:
    """``2026-11-24T06:00:13+00:00`` -> ``2026-11-24 06:00``."""
    return iso[:16].replace("T", " ")


def axis_verdicts(report: dict) -> list[AxisVerdict]:
    """Per axis: requirement, the largest |error| of any set-point, where, and pass/fail."""
    out = []
    sps = report["setpoints"]
    for a in AXES:
        over = report["overall"]["axes"][a]
        judged = [sp for sp in sps if sp["axes"][a]["passed"] is not None]
        worst = max(judged, key=lambda sp: _num(sp["axes"][a]["max_abs"]), default=None)
        out.append(
            AxisVerdict(
                axis=a,
                requirement=float(report["requirements"][a]),
                max_abs=_num(over["max_abs"]),
                worst_setpoint=worst["setpoint_index"] if worst else None,
                n_within=sum(1 for sp in judged if sp["axes"][a]["passed"]),
                n_judged=len(judged),
                passed=over["passed"],
            )
        )
    return out


def verdict_line(report: dict) -> str:
    """The campaign's verdict in one sentence, starting PASS, FAIL or NO VERDICT."""
    verdicts = axis_verdicts(report)
    failing = [v for v in verdicts if v.passed is False]
    n_sp = len(report["setpoints"])
    if failing:
        parts = [
            f"{AXIS_NAMES[v.axis]} at {v.n_judged - v.n_within} of {v.n_judged}" for v in failing
        ]
        return (
            f"FAIL: {len(failing)} of {len(AXES)} axes exceed their requirement "
            f"({', '.join(parts)} set-points)."
        )
    if report["overall"]["passed"] is True:
        return f"PASS: every axis is within its requirement at all {n_sp} set-points."
    return "NO VERDICT: no set-point has a pose to judge."


def requirement_source(report: dict) -> str:
    """Where the requirements come from, and the rule they are applied with."""
    req = report["requirements"]
    differ = [a for a in AXES if not math.isclose(float(req[a]), PAPER_REQUIREMENTS[a])]
    values = requirement_values(req)
    if not differ:
        origin = (
            "the campaign's stored requirements, which are the default of a new campaign: "
            f"the accuracy goals of {PAPER}"
        )
    else:
        origin = (
            "the campaign's stored requirements, set when it was created (they differ from "
            f"the paper's goals, the default, on {', '.join(AXIS_NAMES[a] for a in differ)})"
        )
    return (
        f"Requirements ({values}) are {origin}. An axis passes when the largest |error| "
        "after outlier removal is within its requirement at every set-point."
    )


def requirement_values(req: dict[str, float]) -> str:
    """``x and y 6 mm, z 28.3 mm, pitch, yaw and roll 0.15 deg``: axes with equal values
    named together, in axis order."""
    groups: dict[tuple[float, str], list[str]] = {}
    for a in AXES:
        groups.setdefault((float(req[a]), AXIS_UNITS[a]), []).append(AXIS_NAMES[a])
    parts = []
    for (value, unit), names in groups.items():
        named = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
        parts.append(f"{named} {value:g} {unit}")
    return ", ".join(parts)


def reading_notes(report: dict) -> str:
    """How the statistics were computed (outliers, units, sigma ratio)."""
    return (
        "x, y, z in mm in the camera frame; pitch, yaw, roll in deg, facing Euler angles "
        "(docs/architecture.md section 3). Outliers (the paper's singular points, Table 1 -> "
        f"Table 2): within a set-point, an error farther than {SINGULAR_K:g} x "
        f"{MAD_TO_SIGMA} x MAD from its axis's median error; they are left out of the "
        "statistics and counted. 3 sigma is three times the measured standard deviation; "
        "predicted 1-sigma is the median of the uncertainty the pipeline reported per frame; "
        "a sigma ratio near 1 means the reported uncertainty is honest."
    )


def verdict_table(report: dict) -> Table:
    """Axis, requirement, measured max |error|, its share of the requirement, the worst
    set-point, set-points within, result."""
    header = [
        "axis",
        "requirement",
        "measured max |error|",
        "share of requirement",
        "worst set-point",
        "set-points within",
        "result",
    ]
    rows, status = [], {}
    for i, v in enumerate(axis_verdicts(report)):
        rows.append(
            [
                AXIS_NAMES[v.axis],
                with_unit(v.requirement, v.axis),
                with_unit(v.max_abs, v.axis),
                _percent(v.share),
                fmt(v.worst_setpoint),
                f"{v.n_within} of {v.n_judged}",
                fmt(v.passed),
            ]
        )
        if v.passed is not None:
            status[(i, 6)] = status[(i, 2)] = v.passed
    return Table(header, rows, status)


def _percent(share: float | None) -> str:
    """``83 %``; ``-`` when undefined (None or NaN, e.g. no frame at all)."""
    v = _num(share)
    return f"{100.0 * v:.0f} %" if math.isfinite(v) else "-"


# -- findings --------------------------------------------------------------------------------
def findings(report: dict) -> list[str]:
    """Sentences of interpretation with axis names and units, each written only when its
    condition holds (docs/campaigns.md lists the conditions)."""
    sps = report["setpoints"]
    over = report["overall"]["axes"]
    out = []
    if report["overall"]["passed"] is True:
        out.append(f"All {len(sps)} set-points meet every requirement.")
    out += [_failing_sentence(v) for v in axis_verdicts(report) if v.passed is False]
    out += [s for a in AXES if (s := _sigma_sentence(a, over[a]))]
    out += [s for a in AXES if (s := _bias_sentence(a, over[a]))]
    if report["n_frames"] and report["n_ok"] < report["n_frames"]:
        out.append(
            f"{report['n_frames'] - report['n_ok']} of {report['n_frames']} frames gave no "
            f"pose (success rate {report['success_rate']:.1%})."
        )
    removed = {a: over[a]["n_removed"] for a in AXES if over[a]["n_removed"]}
    if removed:
        per_axis = ", ".join(f"{AXIS_NAMES[a]} {n}" for a, n in removed.items())
        out.append(
            f"{sum(removed.values())} outlier(s) removed ({per_axis}): errors farther than "
            f"{SINGULAR_K:g} x {MAD_TO_SIGMA} x MAD from their set-point's median."
        )
    return out


def _failing_sentence(v: AxisVerdict) -> str:
    return (
        f"{AXIS_NAMES[v.axis]}: {v.n_judged - v.n_within} of {v.n_judged} set-points exceed "
        f"the requirement of {with_unit(v.requirement, v.axis)} (worst: set-point "
        f"{v.worst_setpoint}, max |error| {with_unit(v.max_abs, v.axis)})."
    )


def _sigma_sentence(axis: str, d: dict) -> str | None:
    ratio = _num(d["sigma_ratio"])
    if not math.isfinite(ratio) or 0.5 <= ratio <= 2.0:
        return None
    verdict = "too small" if ratio > 2.0 else "conservative"
    return (
        f"{AXIS_NAMES[axis]}: the measured spread (1 sigma {with_unit(d['std'], axis)}) is "
        f"{ratio:.2g} times the pipeline's predicted 1-sigma "
        f"({with_unit(d['predicted_sigma'], axis)}): the reported uncertainty is {verdict} here."
    )


def _bias_sentence(axis: str, d: dict) -> str | None:
    bias, std = _num(d["bias"]), _num(d["std"])
    if not (math.isfinite(bias) and math.isfinite(std) and abs(bias) > 3 * std):
        return None
    return (
        f"{AXIS_NAMES[axis]}: the mean error {with_unit(bias, axis)} is more than 3 standard "
        f"deviations ({with_unit(std, axis)}): a systematic offset (mount or placement error "
        "of the reference?) dominates the noise."
    )


# -- statistics tables -----------------------------------------------------------------------
def axis_tables(axes: dict[str, dict], headers: dict[str, tuple[str, bool]]) -> list[Table]:
    """One table per axis group (translation in mm, attitude in deg), the unit in every
    header that carries one."""
    tables = []
    for name, unit, group in AXIS_GROUPS:
        header = ["axis"] + [f"{h} ({unit})" if has_unit else h for h, has_unit in headers.values()]
        rows, status = [], {}
        for i, a in enumerate(group):
            rows.append([AXIS_NAMES[a]] + [fmt(axes[a][k]) for k in headers])
            if "passed" in headers and axes[a]["passed"] is not None:
                status[(i, len(headers))] = axes[a]["passed"]
        tables.append(Table(header, rows, status, f"{name} ({unit})"))
    return tables


def statistics_tables(axes: dict[str, dict]) -> list[Table]:
    """The error statistics of one set-point or the whole campaign."""
    return axis_tables(axes, STAT_HEADERS)


def measured_tables(axes: dict[str, dict]) -> list[Table]:
    """The paper-style table of the measured values of one set-point."""
    return axis_tables(axes, MEASURED_HEADERS)


def setpoint_table(report: dict) -> Table:
    """One row per set-point: commanded pose, range, frames with a pose, max |error| per
    axis (marked against its requirement) and the result with the failing axes."""
    header = ["set-point", "commanded (deg; rail mm)", "range (m)", "frames with a pose"]
    header += [f"{AXIS_NAMES[a]} max |error| ({AXIS_UNITS[a]})" for a in AXES] + ["result"]
    rows, status = [], {}
    for i, sp in enumerate(report["setpoints"]):
        z_mm = _num(sp["reference"]["z_mm"])
        commanded = commanded_text(sp.get("commanded") or {})
        if sp.get("camera"):
            commanded += f"; {setting_text(sp['camera'])}"
        row = [
            str(sp["setpoint_index"]),
            commanded,
            fmt(z_mm / 1000.0),
            f"{sp['n_ok']} of {sp['n_frames']}",
        ]
        for j, a in enumerate(AXES):
            row.append(fmt(sp["axes"][a]["max_abs"]))
            if sp["axes"][a]["passed"] is not None:
                status[(i, 4 + j)] = sp["axes"][a]["passed"]
        failing = [AXIS_NAMES[a] for a in AXES if sp["axes"][a]["passed"] is False]
        row.append(f"FAIL ({', '.join(failing)})" if failing else fmt(sp["passed"]))
        if sp["passed"] is not None:
            status[(i, len(row) - 1)] = sp["passed"]
        rows.append(row)
    return Table(header, rows, status)


SETTING_LABELS = {
    "integration_time_us": ("integration time", "us"),
    "modulation_frequency_mhz": ("modulation", "MHz"),
}


def setting_text(setting: dict | None) -> str:
    """``integration time 200 us, modulation 12 MHz``; ``-`` for none."""
    if not setting:
        return "-"
    return ", ".join(
        f"{SETTING_LABELS[k][0]} {v:g} {SETTING_LABELS[k][1]}"
        for k, v in setting.items()
        if k in SETTING_LABELS
    )


def commanded_text(commanded: dict) -> str:
    """``yaw 5, pitch 0, roll 0, rail 11000``; axes the set-point left alone are omitted."""
    parts = [
        f"{name} {commanded[name]:g}"
        for name, _ in COMMANDED_AXES
        if commanded.get(name) is not None
    ]
    return ", ".join(parts) or "-"
