"""Dynamic accuracy of a pose sensor: the reference's angular rate, and the measurement
latency found by aligning the measured attitude with the reference.

Conventions: ``R`` is ``R_camera_target`` (N, 3, 3); an angular rate ``w`` is in the
camera frame with dR/dt = [w]x R (the relative-state filter's ``angular_rate_deg_s``).

Latency model. A frame stamped at ``t`` measures the attitude the reference had at
``t - delay``: ``R_meas(t) = R_ref(t - delay) . exp([b]x) . noise`` with a constant offset
``b`` (target frame: the bench's mount error, a calibration residual). The delay is what a
GNC loop must compensate: the stamp's lag behind the middle of the exposure (a ToF frame
integrates four phase sub-frames), transfer and host time-stamping. It is fitted by least
squares over the frames in motion (a one-dimensional search, the offset solved in closed
form for each trial delay); its standard deviation is the Gauss-Newton one, inflated by the
residuals' lag-one autocorrelation (motion artefacts make neighbouring frames' errors
alike, so they carry less information than independent ones).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation, RotationSpline


@dataclass(frozen=True)
class LatencyFit:
    """Result of ``fit_latency``.

    delay_s : the measured attitude lags the reference by this (s; > 0: late).
    sigma_s : its standard deviation (s), after the autocorrelation inflation.
    offset_deg : (3,) the constant rotation-vector offset ``log(R_ref^T R_meas)`` (deg,
        target frame) at the fitted delay.
    residual_rms_deg : RMS of the attitude residual about the offset (deg).
    n_frames : frames used; n_effective : their number after the autocorrelation.
    peak_rate_deg_s : the largest reference rate over them (what makes a delay visible).
    """

    delay_s: float
    sigma_s: float
    offset_deg: np.ndarray
    residual_rms_deg: float
    n_frames: int
    n_effective: float
    peak_rate_deg_s: float


def reference_spline(times_s: np.ndarray, R: np.ndarray) -> RotationSpline:
    """A C2 rotation spline through the reference attitudes (``times_s`` (N,) increasing,
    ``R`` (N, 3, 3)): attitude and rate between the frames."""
    return RotationSpline(np.asarray(times_s, float), Rotation.from_matrix(R))


def angular_rate_deg_s(spline: RotationSpline, at_s: np.ndarray) -> np.ndarray:
    """(M, 3) camera-frame angular rate (deg/s) of the reference at ``at_s`` (M,). The
    spline gives the body (target-frame) rate; ``R @ w_body`` is the camera-frame one."""
    at_s = np.asarray(at_s, float)
    body = np.atleast_2d(spline(at_s, 1))
    R = spline(at_s).as_matrix().reshape(-1, 3, 3)
    return np.degrees(np.einsum("nij,nj->ni", R, body))


def _residuals(spline: RotationSpline, t_s: np.ndarray, R_meas: Rotation, delay_s: float):
    """(M, 3) rotation vectors log(R_ref(t - delay)^T R_meas) (rad)."""
    return (spline(t_s - delay_s).inv() * R_meas).as_rotvec()


def fit_latency(
    times_s: np.ndarray,
    R_meas: np.ndarray,
    ref_times_s: np.ndarray,
    R_ref: np.ndarray,
    *,
    max_delay_s: float = 0.5,
) -> LatencyFit:
    """Fit the delay of measured attitudes behind a reference (module docstring).

    times_s : (M,) stamps of the measured frames (only good poses); R_meas : (M, 3, 3).
    ref_times_s : (N,) increasing, R_ref : (N, 3, 3) the reference over a span that covers
    ``times_s - d`` for every trial delay ``|d| <= max_delay_s`` (frames whose shifted time
    falls outside the reference are left out).
    Raises ValueError with the reason when the frames cannot show a delay (too few, or a
    reference that does not move).
    """
    times_s = np.asarray(times_s, float)
    ref_times_s = np.asarray(ref_times_s, float)
    if len(ref_times_s) < 4:
        raise ValueError(f"a latency fit needs >= 4 reference samples, got {len(ref_times_s)}")
    spline = reference_spline(ref_times_s, R_ref)
    inside = (times_s - max_delay_s >= ref_times_s[0]) & (times_s + max_delay_s <= ref_times_s[-1])
    t = times_s[inside]
    if len(t) < 5:
        raise ValueError(
            f"{len(t)} measured frames lie within the reference span (need >= 5): the "
            "reference must cover the frames' times +/- the largest delay searched"
        )
    meas = Rotation.from_matrix(np.asarray(R_meas, float)[inside])
    rate = np.linalg.norm(angular_rate_deg_s(spline, t), axis=1)
    peak = float(rate.max())

    def cost(d: float) -> float:
        e = _residuals(spline, t, meas, d)
        return float(np.sum((e - e.mean(axis=0)) ** 2))

    grid = np.linspace(-max_delay_s, max_delay_s, 41)
    best = grid[int(np.argmin([cost(d) for d in grid]))]
    step = grid[1] - grid[0]
    sol = minimize_scalar(
        cost,
        bounds=(max(best - step, -max_delay_s), min(best + step, max_delay_s)),
        method="bounded",
        options={"xatol": 1e-6},
    )
    delay = float(sol.x)
    e = _residuals(spline, t, meas, delay)
    offset = e.mean(axis=0)
    r = e - offset
    n = len(t)
    dof = max(3 * n - 4, 1)  # 3 offset components and the delay
    s2 = float(np.sum(r**2)) / dof
    h = 1e-4
    J = (_residuals(spline, t, meas, delay + h) - _residuals(spline, t, meas, delay - h)) / (2 * h)
    J = J - J.mean(axis=0)  # the offset absorbs the mean
    info = float(np.sum(J**2))
    if not info > 0 or peak < 1e-6:
        raise ValueError("the reference does not move over these frames: no delay is visible")
    rho = _lag_one_autocorrelation(r)
    n_eff = n * (1 - rho) / (1 + rho)
    sigma = np.sqrt(s2 / info) * np.sqrt(n / max(n_eff, 1.0))
    return LatencyFit(
        delay_s=delay,
        sigma_s=float(sigma),
        offset_deg=np.degrees(offset),
        residual_rms_deg=float(np.degrees(np.sqrt(np.mean(np.sum(r**2, axis=1))))),
        n_frames=n,
        n_effective=float(n_eff),
        peak_rate_deg_s=peak,
    )


def _lag_one_autocorrelation(r: np.ndarray) -> float:
    """Lag-one autocorrelation of an (M, 3) residual series, pooled over its components,
    clipped to [0, 0.95] (a negative one would shrink the sigma; we do not claim that)."""
    a, b = r[:-1], r[1:]
    den = float(np.sum(r * r))
    if den <= 0 or len(r) < 3:
        return 0.0
    return float(np.clip(np.sum(a * b) / den, 0.0, 0.95))
