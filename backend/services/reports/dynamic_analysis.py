"""The dynamic section of a campaign report (docs/campaigns.md, "Dynamic campaigns"):
accuracy while a motion profile runs against accuracy at rest, the relative-state
filter's angular rate against the reference's, the frames lost in motion, and the
measurement latency. Pure numpy/scipy on the report's rows.

Per dynamic set-point (rows with ``in_motion`` 0 or 1):

- attitude error per axis (facing Euler, measured minus reference) in motion and at rest
  (the rests before and after the profile): RMS and max |error|, no singular-point
  removal (a dynamic error is not an outlier);
- angular rate: the reference's, camera frame, from a rotation spline through the
  reference attitudes of every frame (``tofpose.lab.dynamics``), against the filter's
  ``rate_*`` columns at the same stamps; RMS and max of the error norm in motion, and
  the RMS as a share of the reference's peak rate;
- frames lost in motion: frames the camera numbered between the first and the last in
  motion that gave no good pose (not delivered, or no pose), as a share of them;
- latency: ``tofpose.lab.dynamics.fit_latency`` over the good frames in motion, and an
  inverse-variance mean over the set-points with a chi-square of their agreement.
"""

from __future__ import annotations

import numpy as np

from backend.services.reports.analysis import REFERENCE_PREFIX
from tofpose.core.geometry import FACING, rotation_from_euler_deg
from tofpose.lab.dynamics import angular_rate_deg_s, fit_latency, reference_spline

ANGLES = ("pitch_deg", "yaw_deg", "roll_deg")
RATES = tuple(f"rate_{a}_deg_s" for a in "xyz")


def _num(v) -> float:
    try:
        return float(v) if v is not None and v != "" else np.nan
    except (TypeError, ValueError):
        return np.nan


def _rotations(rows: list[dict], prefix: str) -> np.ndarray:
    """(N, 3, 3) R_camera_target from the facing Euler columns ``prefix + angle``."""
    return np.array(
        [rotation_from_euler_deg(*(_num(r[prefix + a]) for a in ANGLES)) @ FACING for r in rows]
    ).reshape(-1, 3, 3)


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _max_abs(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.max(np.abs(x))) if x.size else float("nan")


def setpoint_dynamics(rows: list[dict], reference: str) -> dict:
    """The dynamic statistics of one set-point's rows (module docstring)."""
    prefix = REFERENCE_PREFIX[reference]
    rows = sorted(rows, key=lambda r: _num(r["time_s"]))
    # one row per stamp (a spline needs increasing times; a repeated stamp is a duplicate)
    t_all = [_num(r["time_s"]) for r in rows]
    rows = [r for k, r in enumerate(rows) if k == 0 or t_all[k] > t_all[k - 1]]
    t = np.array([_num(r["time_s"]) for r in rows])
    moving = np.array([_num(r["in_motion"]) == 1 for r in rows])
    ok = np.array([str(r["ok"]) in ("1", "True") for r in rows])
    has_ref = np.array([np.isfinite(_num(r[prefix + "yaw_deg"])) for r in rows])
    out: dict = {
        "n_frames": len(rows),
        "n_in_motion": int(moving.sum()),
        "n_ok_in_motion": int((moving & ok).sum()),
    }
    idx = np.array([_num(r["frame_index"]) for r in rows])
    if moving.any():
        span = int(idx[moving].max() - idx[moving].min() + 1)
        out["expected_in_motion"] = span
        out["lost_in_motion_share"] = 1.0 - out["n_ok_in_motion"] / span
        out["motion_s"] = float(np.ptp(t[moving]))
    error = {}
    for a in ANGLES:
        e = np.array([_num(r[a]) - _num(r[prefix + a]) for r in rows])
        e[~ok] = np.nan
        error[a] = e
        out[a] = {
            "rms_in_motion": _rms(e[moving]),
            "max_in_motion": _max_abs(e[moving]),
            "rms_at_rest": _rms(e[~moving]),
            "max_at_rest": _max_abs(e[~moving]),
        }
    series = {
        "t": t.tolist(),
        "in_motion": moving.astype(int).tolist(),
        "error": {a: error[a].tolist() for a in ANGLES},
    }
    if has_ref.sum() >= 4:
        spline = reference_spline(
            t[has_ref], _rotations([r for r, h in zip(rows, has_ref, strict=True) if h], prefix)
        )
        inside = (t >= t[has_ref][0]) & (t <= t[has_ref][-1])
        w_ref = np.full((len(t), 3), np.nan)
        w_ref[inside] = angular_rate_deg_s(spline, t[inside])
        w_meas = np.array([[_num(r[c]) for c in RATES] for r in rows]).reshape(-1, 3)
        err = np.linalg.norm(w_meas - w_ref, axis=1)
        peak = float(np.nanmax(np.linalg.norm(w_ref[moving], axis=1))) if moving.any() else 0.0
        axis = int(np.nanargmax(np.nanmax(np.abs(w_ref), axis=0)))
        out["rate"] = {
            "peak_reference_deg_s": peak,
            "rms_error_in_motion_deg_s": _rms(err[moving]),
            "max_error_in_motion_deg_s": _max_abs(err[moving]),
            "rms_error_at_rest_deg_s": _rms(err[~moving]),
            "rms_error_share_of_peak": _rms(err[moving]) / peak if peak > 0 else None,
            "component": "xyz"[axis],
        }
        series["rate_reference"] = w_ref[:, axis].tolist()
        series["rate_measured"] = w_meas[:, axis].tolist()
        good = ok & inside & moving  # at rest a frame shows no delay, only noise
        try:
            fit = fit_latency(
                t[good],
                _rotations([r for r, g in zip(rows, good, strict=True) if g], ""),
                t[has_ref],
                spline(t[has_ref]).as_matrix(),
            )
            out["latency"] = {
                "delay_s": fit.delay_s,
                "sigma_s": fit.sigma_s,
                "residual_rms_deg": fit.residual_rms_deg,
                "n_frames": fit.n_frames,
                "n_effective": fit.n_effective,
            }
        except ValueError as exc:
            out["latency"] = {"why_none": str(exc)}
    out["series"] = series
    return out


def pooled_latency(fits: list[dict]) -> dict | None:
    """Inverse-variance mean of the set-points' delays, its sigma, and the chi-square of
    their agreement with it (about len - 1 when they agree within their sigmas)."""
    good = [f for f in fits if f.get("sigma_s")]
    if not good:
        return None
    d = np.array([f["delay_s"] for f in good])
    s = np.array([f["sigma_s"] for f in good])
    w = 1.0 / s**2
    mean = float(np.sum(w * d) / np.sum(w))
    return {
        "delay_s": mean,
        "sigma_s": float(1.0 / np.sqrt(np.sum(w))),
        "chi2": float(np.sum(w * (d - mean) ** 2)),
        "n_setpoints": len(good),
    }


def analyse_dynamic(rows: list[dict], reference: str) -> dict | None:
    """{"setpoints": {index: stats}, "latency": pooled} of the dynamic set-points, or
    None when the campaign has none."""
    by_sp: dict[int, list[dict]] = {}
    for r in rows:
        if r.get("in_motion") not in (None, ""):
            by_sp.setdefault(int(r["setpoint_index"]), []).append(r)
    if not by_sp:
        return None
    per = {k: setpoint_dynamics(v, reference) for k, v in sorted(by_sp.items())}
    fits = [s["latency"] for s in per.values() if "delay_s" in s.get("latency", {})]
    return {"setpoints": per, "latency": pooled_latency(fits)}


def is_static(row: dict) -> bool:
    """Rows the static statistics use: frames at a static set-point or at rest."""
    return _num(row.get("in_motion")) != 1
