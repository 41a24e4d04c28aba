"""A study cell's verdict against its requirements, and the study's in one paragraph.

The rule (printed in every report): a cell meets an axis' requirement when at least
``percentile`` % of its frames have a pose whose |error| on that axis is within the
requirement; a frame without a pose counts as beyond every requirement. The number that
decides it is the ``percentile``-th percentile of |error| over all the cell's frames
(numpy's ``inverted_cdf``: the smallest |error| that at least ``percentile`` % of the
frames are within, so "percentile <= requirement" and "at least ``percentile`` % of the
frames within" are the same statement); it is undefined when that percentile falls on
frames without a pose. A cell passes when it meets every axis. Axes and errors:
``tofpose.study.axis_errors`` (the campaign's: x, y, z mm and facing pitch, yaw, roll
deg).

Every frame not within all requirements is given a failure mode: ``no pose: <the
pipeline's reason, without its numbers>``, ``no pose and no recorded reason`` (a refused
frame whose reason is empty), or ``<axis> beyond <requirement>`` (a pose, outside the
requirement on the axis it misses by the largest share). A cell names its most common
one.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tofpose.lab.requirements import REQUIREMENT_AXES, axis_unit
from tofpose.study.spec import StudyRequirements

NO_REASON = "no pose and no recorded reason"


def reason_kind(reason: str) -> str:
    """A failure reason without its numbers: the words before the first ':' or '('."""
    for sep in (":", "("):
        reason = reason.split(sep)[0]
    return reason.strip() or "unknown"


def axis_name(axis: str) -> str:
    """``pitch_deg`` -> ``pitch``."""
    return axis.rsplit("_", 1)[0]


def with_unit(value: float, axis: str) -> str:
    """``0.15 deg``, ``28.3 mm``: 3 significant digits and the axis' unit."""
    return f"{value:.3g} {axis_unit(axis)}"


def share_pct(share: float) -> str:
    """A share of a requirement in %: whole numbers, one decimal near 100 % (so that
    28.4 of 28.3 reads 100.4, not 100)."""
    pct = 100.0 * share
    return f"{pct:.1f}" if abs(pct - 100.0) < 0.5 else f"{pct:.0f}"


def requirement_values(req: StudyRequirements) -> str:
    """``x and y 6 mm, z 28.3 mm, pitch, yaw and roll 0.15 deg``: axes with equal values
    grouped, in ``REQUIREMENT_AXES`` order."""
    groups: list[tuple[float, str, list[str]]] = []
    for a in REQUIREMENT_AXES:
        v, unit = req.axis(a), axis_unit(a)
        if groups and groups[-1][0] == v and groups[-1][1] == unit:
            groups[-1][2].append(axis_name(a))
        else:
            groups.append((v, unit, [axis_name(a)]))
    parts = []
    for v, unit, names in groups:
        head = ", ".join(names[:-1]) + " and " + names[-1] if len(names) > 1 else names[0]
        parts.append(f"{head} {v:g} {unit}")
    return ", ".join(parts)


def rule_text(req: StudyRequirements) -> str:
    """The rule of the module docstring, with ``req``'s numbers, as a report prints it."""
    p = f"{req.percentile:g}"
    return (
        f"Requirements: {requirement_values(req)}. A cell meets an axis' requirement when at "
        f"least {p} % of its frames have a pose within it (the p{p} of |error| over all its "
        "frames is within the requirement; a frame without a pose counts as beyond it); a "
        "cell passes when it meets every axis. Errors are estimate minus truth: x, y, z of "
        "the target's origin in the camera frame, pitch, yaw, roll the facing Euler angles."
    )


@dataclass(frozen=True)
class AxisJudgement:
    """One axis of a cell: its requirement, the deciding percentile of |error| (None
    when it falls on frames without a pose), the share of frames within (%), pass."""

    axis: str
    requirement: float
    value: float | None
    within_pct: float
    passed: bool

    @property
    def share(self) -> float:
        """value / requirement (inf when the value is undefined)."""
        return math.inf if self.value is None else self.value / self.requirement


@dataclass(frozen=True)
class CellVerdict:
    """A cell's verdict (module docstring). ``passed`` None: no frames to judge.
    ``deciding``: the axis whose number decides (the worst failing axis, or the one
    closest to its requirement in a passing cell); ``text``: the verdict in words, with
    that number."""

    passed: bool | None
    frames: int
    no_pose: int
    percentile: float
    axes: tuple[AxisJudgement, ...]
    deciding: str | None
    within_all_pct: float | None
    failure_modes: dict[str, int]
    main_failure: str | None
    number: str
    text: str

    def to_dict(self) -> dict:
        """For summary.json: the fields, axes by name."""
        return {
            "passed": self.passed,
            "frames": self.frames,
            "no_pose": self.no_pose,
            "percentile": self.percentile,
            "axes": {
                j.axis: {
                    "requirement": j.requirement,
                    "value": j.value,
                    "within_pct": j.within_pct,
                    "passed": j.passed,
                }
                for j in self.axes
            },
            "deciding": self.deciding,
            "within_all_pct": self.within_all_pct,
            "failure_modes": self.failure_modes,
            "main_failure": self.main_failure,
            "number": self.number,
            "text": self.text,
        }


def _failure_modes(errors: np.ndarray, reasons: Sequence[str], req: np.ndarray) -> Counter:
    modes: Counter = Counter()
    for e, reason in zip(errors, reasons, strict=True):
        if not np.all(np.isfinite(e)):
            modes["no pose: " + reason_kind(reason) if reason.strip() else NO_REASON] += 1
            continue
        share = np.abs(e) / req
        k = int(np.argmax(share))
        if share[k] > 1.0:
            a = REQUIREMENT_AXES[k]
            modes[f"{axis_name(a)} beyond {with_unit(req[k], a)}"] += 1
    return modes


def judge_cell(
    errors: np.ndarray, reasons: Sequence[str], requirements: StudyRequirements
) -> CellVerdict:
    """The verdict of one cell. ``errors``: its frames' errors on ``REQUIREMENT_AXES``,
    shape (N, 6) (mm, deg; NaN rows for frames without a pose,
    ``axis_errors.requirement_axis_errors``); ``reasons``: the pipeline's reason per
    frame, (N,) (empty for a pose)."""
    errors = np.asarray(errors, float).reshape(-1, 6)
    n = len(errors)
    p = requirements.percentile
    req = np.array([requirements.axis(a) for a in REQUIREMENT_AXES])
    has_pose = np.all(np.isfinite(errors), axis=1)
    no_pose = int(n - has_pose.sum())
    if n == 0:
        return CellVerdict(None, 0, 0, p, (), None, None, {}, None, "-", "no frames stored")
    abs_err = np.where(has_pose[:, None], np.abs(errors), np.inf)
    deciding_values = np.percentile(abs_err, p, axis=0, method="inverted_cdf")
    judged = []
    for k, a in enumerate(REQUIREMENT_AXES):
        v = float(deciding_values[k])
        judged.append(
            AxisJudgement(
                axis=a,
                requirement=float(req[k]),
                value=v if math.isfinite(v) else None,
                within_pct=100.0 * float(np.sum(abs_err[:, k] <= req[k])) / n,
                passed=bool(v <= req[k]),
            )
        )
    passed = all(j.passed for j in judged)
    within_all = 100.0 * float(np.sum(np.all(abs_err <= req, axis=1))) / n
    modes = _failure_modes(errors, reasons, req)
    main = None
    if modes:
        mode, count = max(modes.items(), key=lambda kv: (kv[1], kv[0]))
        main = f"{mode} ({count} of {n} frames)"
    pool = judged if passed else [j for j in judged if not j.passed]
    worst = max(pool, key=lambda j: j.share)
    pct = f"p{p:g}"
    if worst.value is None:
        number = (
            f"no pose in {no_pose} of {n} frames ({100.0 * no_pose / n:.1f} %), more than "
            f"the {100.0 - p:g} % a {pct} requirement allows"
        )
    else:
        number = (
            f"{axis_name(worst.axis)} {pct} |error| {with_unit(worst.value, worst.axis)} = "
            f"{share_pct(worst.share)} % of {with_unit(worst.requirement, worst.axis)}"
        )
    if passed:
        text = f"PASS: every axis within its requirement; closest {number}"
    else:
        text = f"FAIL: {number}"
    return CellVerdict(
        passed=passed,
        frames=n,
        no_pose=no_pose,
        percentile=p,
        axes=tuple(judged),
        deciding=worst.axis,
        within_all_pct=within_all,
        failure_modes=dict(sorted(modes.items())),
        main_failure=main,
        number=number,
        text=text,
    )


def _severity(cell: dict) -> tuple[int, float]:
    """How badly a cell (summary.json's, with its ``verdict``) misses: undefined
    deciding numbers (too many frames without a pose) before any finite share."""
    v = cell["verdict"]
    if v["passed"] is None:
        return (-1, 0.0)
    j = v["axes"][v["deciding"]]
    if j["value"] is None:
        return (1, v["no_pose"] / max(v["frames"], 1))
    return (0, j["value"] / j["requirement"])


def study_verdict(cells: Sequence[dict], requirements: StudyRequirements) -> dict:
    """The study in one paragraph: how many cells pass, the worst cell and why.
    ``cells``: summary.json's cells, each with its ``verdict`` (``CellVerdict.to_dict``)
    and ``label``. Returns {"cells_passed", "cells_judged", "passed", "worst_cell",
    "text"}."""
    judged = [c for c in cells if c["verdict"]["passed"] is not None]
    n_pass = sum(1 for c in judged if c["verdict"]["passed"])
    rule = (
        f"the requirements ({requirement_values(requirements)}, each in at least "
        f"{requirements.percentile:g} % of a cell's frames)"
    )
    if not judged:
        return {
            "cells_passed": 0,
            "cells_judged": 0,
            "passed": None,
            "worst_cell": None,
            "text": "No cell has stored frames yet: nothing to judge.",
        }
    worst = max(judged, key=_severity)
    wv = worst["verdict"]
    unjudged = len(cells) - len(judged)
    tail = f" {unjudged} cells have no frames stored." if unjudged else ""
    if n_pass == len(judged):
        text = (
            f"PASS: all {len(judged)} cells meet {rule}. The closest to its requirement is "
            f"cell {worst['cell']} ({worst['label']}): {wv['number']}." + tail
        )
    else:
        text = (
            f"FAIL: {n_pass} of {len(judged)} cells meet {rule}. The worst is cell "
            f"{worst['cell']} ({worst['label']}): {wv['number']}"
            + (f"; main failure: {wv['main_failure']}" if wv["main_failure"] else "")
            + "."
            + tail
        )
    return {
        "cells_passed": n_pass,
        "cells_judged": len(judged),
        "passed": n_pass == len(judged),
        "worst_cell": worst["cell"],
        "text": text,
    }
