"""Accuracy statistics of a campaign (docs/campaigns.md, "Reports"). Pure numpy on rows.

Errors are measured minus reference per axis: x, y, z in mm and the facing Euler angles
pitch, yaw, roll in degrees (docs/architecture.md §3). The reference is the lab's
(``lab``: encoders + nominal geometry, what a real lab has; ``calibrated``: encoders + a
bench calibration) or, on the simulator, the truth: the pose it rendered (``truth``;
``exact`` is its older name).

Singular-point removal (the paper's Table 1 -> Table 2): within a set-point, an error
farther than ``SINGULAR_K`` scaled MADs (1.4826 x median absolute deviation, a robust
sigma) from the median error of its axis is a singular point and is left out of that
axis's statistics. The rule is printed in every report.

Pass/fail: a set-point meets an axis's requirement when its largest |error| after
singular-point removal is within it; the campaign meets it when every set-point does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

AXES = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")
SIGMA_COLUMNS = dict(
    zip(
        AXES,
        (
            "sigma_x_mm",
            "sigma_y_mm",
            "sigma_z_mm",
            "sigma_pitch_deg",
            "sigma_yaw_deg",
            "sigma_roll_deg",
        ),
        strict=True,
    )
)
SINGULAR_K = 5.0
MAD_TO_SIGMA = 1.4826
RULE = (
    f"singular point: |error - median| > {SINGULAR_K:g} x {MAD_TO_SIGMA} x MAD of its axis "
    "within its set-point; pass: max |error| after removal <= requirement"
)
REFERENCE_PREFIX = {
    "lab": "reference_",
    "calibrated": "calibrated_reference_",
    "truth": "truth_",
    "exact": "truth_",  # the older name of "truth"
}
"""The columns a report's errors are measured against, per ``reference``: ``reference_*``
the lab's reference (encoders + nominal geometry), ``calibrated_reference_*`` the same
with a calibration's mount and placement, ``truth_*`` the pose the simulator rendered
(docs/interop.md, "Names: truth and reference")."""


@dataclass
class AxisStats:
    """Statistics of one axis over a set of frames (NaN where undefined)."""

    n: int
    n_removed: int
    bias: float
    std: float
    rms: float
    max_abs: float
    three_sigma: float
    average: float  # of the measured values (the paper's table)
    maximum: float
    minimum: float
    fluctuation: float  # maximum - minimum
    predicted_sigma: float  # median of the pipeline's own 1-sigma
    sigma_ratio: float  # observed std / predicted sigma
    requirement: float
    passed: bool | None


def keep_mask(errors: np.ndarray) -> np.ndarray:
    """Boolean (N,): True for errors that are not singular points (see module)."""
    e = np.asarray(errors, float)
    if e.size < 3:
        return np.ones(e.shape, bool)
    med = np.median(e)
    mad = MAD_TO_SIGMA * np.median(np.abs(e - med))
    if mad == 0.0:
        return np.ones(e.shape, bool)
    return np.abs(e - med) <= SINGULAR_K * mad


def axis_stats(
    measured: np.ndarray,
    reference: np.ndarray,
    predicted_sigma: np.ndarray,
    requirement: float,
    *,
    remove_singular: bool = True,
) -> AxisStats:
    """Statistics of ``measured - reference`` (arrays (N,), NaN-free) for one axis."""
    m = np.asarray(measured, float)
    err = m - np.asarray(reference, float)
    keep = keep_mask(err) if remove_singular else np.ones(err.shape, bool)
    e, mk = err[keep], m[keep]
    n = int(e.size)
    nan = float("nan")
    sig = np.asarray(predicted_sigma, float)
    sig = sig[np.isfinite(sig)]
    pred = float(np.median(sig)) if sig.size else nan
    std = float(np.std(e, ddof=1)) if n > 1 else nan
    max_abs = float(np.max(np.abs(e))) if n else nan
    return AxisStats(
        n=n,
        n_removed=int(err.size - n),
        bias=float(np.mean(e)) if n else nan,
        std=std,
        rms=float(np.sqrt(np.mean(e**2))) if n else nan,
        max_abs=max_abs,
        three_sigma=3.0 * std,
        average=float(np.mean(mk)) if n else nan,
        maximum=float(np.max(mk)) if n else nan,
        minimum=float(np.min(mk)) if n else nan,
        fluctuation=float(np.max(mk) - np.min(mk)) if n else nan,
        predicted_sigma=pred,
        sigma_ratio=std / pred if pred > 0 and np.isfinite(std) else nan,
        requirement=float(requirement),
        passed=bool(max_abs <= requirement) if n else None,
    )


def _column(rows: Sequence[dict], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else float(r[key]) for r in rows], float)


def analyse(
    rows: Sequence[dict],
    requirements: dict[str, float],
    reference: str = "lab",
) -> dict:
    """Per-set-point and whole-campaign statistics of frame ``rows`` (dicts with the CSV
    columns: ``setpoint_index``, ``ok``, the pose, ``truth_*``, ``reference_*``,
    ``sigma_*``). Returns plain data (JSON-ready)."""
    prefix = REFERENCE_PREFIX[reference]
    by_sp: dict[int, list[dict]] = {}
    for r in rows:
        by_sp.setdefault(int(r["setpoint_index"]), []).append(r)
    per_sp: list[dict[str, Any]] = []
    pooled: dict[str, list[np.ndarray]] = {a: [] for a in AXES}
    for index in sorted(by_sp):
        sp_rows = by_sp[index]
        ok = [r for r in sp_rows if _truthy(r["ok"])]
        entry: dict[str, Any] = {
            "setpoint_index": index,
            "n_frames": len(sp_rows),
            "n_ok": len(ok),
            "success_rate": len(ok) / len(sp_rows) if sp_rows else float("nan"),
            "reference": {a: _nanmean(_column(ok, prefix + a)) for a in AXES},
            "axes": {},
        }
        for a in AXES:
            m, ref = _column(ok, a), _column(ok, prefix + a)
            good = np.isfinite(m) & np.isfinite(ref)
            st = axis_stats(
                m[good], ref[good], _column(ok, SIGMA_COLUMNS[a])[good], requirements[a]
            )
            entry["axes"][a] = asdict(st)
            err = m[good] - ref[good]
            pooled[a].append(err[keep_mask(err)])
        entry["passed"] = _all_passed(entry["axes"])
        per_sp.append(entry)
    overall_axes = {}
    for a in AXES:
        e = np.concatenate(pooled[a]) if pooled[a] else np.zeros(0)
        all_ok = [r for r in rows if _truthy(r["ok"])]
        st = axis_stats(
            e,
            np.zeros_like(e),
            _column(all_ok, SIGMA_COLUMNS[a]),
            requirements[a],
            remove_singular=False,
        )
        d = asdict(st)
        d["n_removed"] = sum(sp["axes"][a]["n_removed"] for sp in per_sp)
        for k in ("average", "maximum", "minimum", "fluctuation"):
            d[k] = float("nan")  # measured-value table is per set-point only
        passes = [sp["axes"][a]["passed"] for sp in per_sp if sp["axes"][a]["passed"] is not None]
        d["passed"] = all(passes) if passes else None
        overall_axes[a] = d
    n_ok = sum(1 for r in rows if _truthy(r["ok"]))
    # which pose an ok row holds: the pixel-level fit's, or the centroid pose where the
    # fit ran and fell back (an older CSV has no column: the fit did not run)
    fitted = [r.get("pixel_fit") for r in rows if _truthy(r["ok"]) and r.get("pixel_fit")]
    return {
        "reference": reference,
        "rule": RULE,
        "requirements": dict(requirements),
        "n_frames": len(rows),
        "n_ok": n_ok,
        "success_rate": n_ok / len(rows) if rows else float("nan"),
        "n_pixel_fit_tried": len(fitted),
        "n_pixel_fit": sum(1 for f in fitted if f == "ok"),
        "setpoints": per_sp,
        "overall": {"axes": overall_axes, "passed": _all_passed(overall_axes)},
    }


def _truthy(v) -> bool:
    return v in (True, 1, "1", "true", "True")


def _nanmean(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def _all_passed(axes: dict[str, dict]) -> bool | None:
    flags = [d["passed"] for d in axes.values() if d["passed"] is not None]
    return all(flags) if flags else None


def findings(result: dict) -> list[str]:
    """Sentences of interpretation, each written only when its condition holds."""
    out = []
    sps = result["setpoints"]
    over = result["overall"]["axes"]
    if result["overall"]["passed"] is True:
        out.append(f"All {len(sps)} set-points meet every requirement.")
    for a, d in over.items():
        failing = [sp["setpoint_index"] for sp in sps if sp["axes"][a]["passed"] is False]
        if failing:
            worst = max(sps, key=lambda sp: _nan_to(sp["axes"][a]["max_abs"], -1.0))
            out.append(
                f"{a}: {len(failing)} of {len(sps)} set-points exceed the requirement of "
                f"{d['requirement']:g} (worst: set-point {worst['setpoint_index']}, max |error| "
                f"{worst['axes'][a]['max_abs']:.3g})."
            )
    for a, d in over.items():
        ratio = d["sigma_ratio"]
        if np.isfinite(ratio) and ratio > 2.0:
            out.append(
                f"{a}: the observed spread is {ratio:.1f}x the pipeline's predicted 1-sigma: "
                "the reported uncertainty is too small here."
            )
        elif np.isfinite(ratio) and ratio < 0.5:
            out.append(
                f"{a}: the observed spread is {ratio:.2f}x the pipeline's predicted 1-sigma: "
                "the reported uncertainty is conservative here."
            )
    for a, d in over.items():
        if np.isfinite(d["bias"]) and np.isfinite(d["std"]) and abs(d["bias"]) > 3 * d["std"]:
            out.append(
                f"{a}: the mean error {d['bias']:.3g} is more than 3 standard deviations "
                f"({d['std']:.3g}): a systematic offset (mount or placement error of the "
                "reference?) dominates the noise."
            )
    if result["n_frames"] and result["n_ok"] < result["n_frames"]:
        out.append(
            f"{result['n_frames'] - result['n_ok']} of {result['n_frames']} frames gave no "
            f"pose (success rate {result['success_rate']:.1%})."
        )
    tried, held = result.get("n_pixel_fit_tried", 0), result.get("n_pixel_fit", 0)
    if tried:
        out.append(
            f"{held} of the {result['n_ok']} poses are the pixel-level fit's"
            + (
                f"; on {tried - held} it fell back to the centroid pose, and the "
                "statistics pool both"
                if held < tried
                else ""
            )
            + (
                f"; {result['n_ok'] - tried} were measured without it"
                if tried < result["n_ok"]
                else ""
            )
            + "."
        )
    removed = sum(d["n_removed"] for d in over.values())
    if removed:
        out.append(f"{removed} singular point(s) removed over all axes ({RULE.split(';')[0]}).")
    return out


def _nan_to(v: float, fill: float) -> float:
    return v if np.isfinite(v) else fill
