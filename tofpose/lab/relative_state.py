"""Relative state for GNC: pose, angular rate and velocity with their covariance, from
the pipeline's poses (ours; the paper measures static poses only).

An error-state Kalman filter on SE(3) x R^6. Nominal state: the attitude R
(``R_camera_target``), the position t (mm, camera frame), the angular rate w (rad/s,
camera frame: ``dR/dt = [w]x R``) and the velocity v (mm/s, camera frame). Error state
(12,): ``(dtheta, dt, dw, dv)`` with the attitude error a left perturbation in the
camera frame, ``R = exp([dtheta]x) R_hat``: the convention of the pipeline's reported
covariance (rotation vector rad, translation mm), so a pose and its covariance are the
measurement as they come.

Motion model: a constant twist (constant angular rate and constant velocity on SE(3)):
``dR/dt = [w]x R``, ``dt/dt = v``, ``dw/dt = 0``, ``dv/dt = w x v``. Between frames the
target moves as ``T <- Exp(xi dt) T`` with the camera-frame twist ``xi = (w, v - w x t)``,
so a constant-rate rotation about *any* fixed point (the camera turned by a turntable,
the target tumbling about its centre, or a point between) is a constant state; a model
with a constant ``v`` would see the target's origin accelerate (centripetally) whenever
the camera turns, by ``|w|^2 |t|`` (~250 mm/s^2 at 20 deg/s and 2 m), and gate the turn.
The twist is driven by white angular and linear acceleration of spectral densities
``angular_accel_psd`` (rad^2 / s^3) and ``linear_accel_psd`` (mm^2 / s^3). An angular
acceleration about a point other than the target's origin also accelerates the origin,
by ``alpha x (t - c)`` for a centre c: the centre is not known (the camera for a
turntable or a chaser's attitude manoeuvre, the target for a tumble), so the origin's
linear acceleration density gets the lever-arm term of the farthest plausible centre,
the camera: ``angular_accel_psd (|t|^2 I - t t^T)`` (the cross-correlation, which
depends on the centre, is left out). The error-state transition and the discrete
process noise over a step dt come from the linearised model's matrix exponential (Van
Loan's method); irregular steps and missed frames are steps of their own length.
A measurement whose squared Mahalanobis
distance of the innovation exceeds ``gate_chi2`` (chi^2 with 6 degrees of freedom) is
rejected and reported as such, not fused; after ``reset_after`` rejections in a row whose
poses agree with each other (the target moved while the filter was blind, or the filter
was wrong) the filter restarts from the newest one, with the rate and velocity of the
last two (their difference over their interval) and the covariance that implies. Why not
filterpy: its Kalman filters assume a vector state that adds, and the attitude does not;
the linear algebra here is a few lines of NumPy (and SciPy's expm), the SE(3) parts would
have to be ours either way.

Constant angular acceleration (``RelativeStateConfig.constant_acceleration()``, the
server's and ``tofpose estimate --filter``'s model): a rate that changes all the time (a
turntable's sine, a nutating tumble) makes a constant-rate model lag; the state then also
holds the twist's acceleration, the angular ``a`` (rad/s^2, ``dw/dt = a``) and the linear
``b`` (mm/s^2, the rate of change of the twist's linear part ``u = v - w x t``), both
random walks: ``da/dt`` white of density ``angular_jerk_psd``, ``db/dt`` white of density
``angular_jerk_psd (f |t|)^2``-shaped (``_lever_arm``), as ``b = -a x c`` for a rotation
about a centre c, taken up to ``f = centre_fraction`` of the range from the camera. So
``dv/dt = w x v + a x t + b`` (18 states; the reported covariance stays the 12 x 12 of pose,
rate and velocity). The fraction trades the two ends: a turntable turns the camera about
an axis next to it (c ~ 0, b ~ 0) and a tumbling target turns about its own centre (c ~ t,
b ~ -a x t); f = 0.55 follows both (docs/algorithm.md, "Relative state"; docs/results.md gives
the measured rate errors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

#: chi^2(6) quantile beyond which a pose is rejected: 1 in 10^4 of consistent poses
DEFAULT_GATE_CHI2 = float(chi2.ppf(1.0 - 1e-4, 6))

Status = Literal["initialised", "updated", "rejected", "reset", "predicted"]

#: a state as table columns (the CSV of ``tofpose estimate --filter``, campaign rows and
#: reports): camera-frame angular rate deg/s and velocity mm/s, their 1-sigma, status
STATE_COLUMNS = (
    "rate_x_deg_s",
    "rate_y_deg_s",
    "rate_z_deg_s",
    "vel_x_mm_s",
    "vel_y_mm_s",
    "vel_z_mm_s",
    "sigma_rate_x_deg_s",
    "sigma_rate_y_deg_s",
    "sigma_rate_z_deg_s",
    "sigma_vel_x_mm_s",
    "sigma_vel_y_mm_s",
    "sigma_vel_z_mm_s",
    "filter_status",
)


@dataclass(frozen=True)
class RelativeStateConfig:
    """Settings of ``RelativeStateFilter``.

    angular_accel_psd : rad^2 / s^3, white angular acceleration (a sine slew of amplitude
        A and period T has peak acceleration A (2 pi / T)^2; q ~ alpha_peak^2 * T / 10
        follows it); linear_accel_psd : mm^2 / s^3;
    initial_rate_sigma_deg_s, initial_velocity_sigma_mm_s : the rate and velocity sigmas
        when the filter starts from a single pose;
    gate_chi2 : innovation gate (module docstring); reset_after : rejections in a row
        after which the filter restarts; max_gap_s : a longer gap without a measurement
        restarts the filter at the next one (the prediction is no longer worth keeping).
    angular_jerk_psd : None for the constant twist (12 states); a value (rad^2 / s^5)
        adds the twist's acceleration to the state, driven by white angular jerk of this
        density (18 states, module docstring: "Constant angular acceleration"); then
        ``angular_accel_psd`` is white acceleration on top of it (may be small),
        ``initial_accel_sigma_deg_s2`` the acceleration's sigma at a start and
        ``centre_fraction`` how far from the camera the centre of the changing rotation
        is taken to be, as a fraction of the range (it sets the density of the twist's
        linear acceleration b; module docstring).
    """

    angular_accel_psd: float = math.radians(10.0) ** 2
    linear_accel_psd: float = 100.0**2
    initial_rate_sigma_deg_s: float = 30.0
    initial_velocity_sigma_mm_s: float = 500.0
    gate_chi2: float = DEFAULT_GATE_CHI2
    reset_after: int = 3
    max_gap_s: float = 10.0
    angular_jerk_psd: float | None = None
    initial_accel_sigma_deg_s2: float = 30.0
    centre_fraction: float = 0.55

    @classmethod
    def constant_acceleration(cls, **changes) -> RelativeStateConfig:
        """The constant-angular-acceleration model tuned for slews and tumbles whose rate
        changes over seconds (a turntable's sine of a few deg and seconds, a nutating
        tumble): white angular jerk of density (30 deg)^2 / s^5, and white angular
        acceleration of (1 deg)^2 / s^3 beside it."""
        base = {
            "angular_accel_psd": math.radians(1.0) ** 2,
            "angular_jerk_psd": math.radians(30.0) ** 2,
        }
        return cls(**{**base, **changes})

    @property
    def n_states(self) -> int:
        """12 (constant twist) or 18 (with the twist's acceleration)."""
        return 12 if self.angular_jerk_psd is None else 18


@dataclass(frozen=True)
class RelativeState:
    """The filter's state at ``time_s``.

    R : (3, 3) R_camera_target; t_mm : (3,); angular_rate_deg_s : (3,) in the camera
    frame; angular_rate_target_deg_s : (3,) the same rate in the target frame;
    velocity_mm_s : (3,) camera frame; covariance : (12, 12) of (dtheta rad, dt mm,
    dw rad/s, dv mm/s) (module docstring); status : what the last step did; innovation_d2
    : squared Mahalanobis distance of the last measurement's innovation (NaN when none);
    n_rejected : rejections in a row.
    """

    time_s: float
    R: np.ndarray
    t_mm: np.ndarray
    angular_rate_deg_s: np.ndarray
    angular_rate_target_deg_s: np.ndarray
    velocity_mm_s: np.ndarray
    covariance: np.ndarray
    status: Status
    innovation_d2: float = float("nan")
    n_rejected: int = 0

    @property
    def angular_rate_sigma_deg_s(self) -> np.ndarray:
        """(3,) 1-sigma of the camera-frame rate."""
        return np.degrees(np.sqrt(np.diag(self.covariance)[6:9]))

    @property
    def velocity_sigma_mm_s(self) -> np.ndarray:
        """(3,) 1-sigma of the velocity."""
        return np.sqrt(np.diag(self.covariance)[9:12])


#: log(2 pi), for the innovation's Gaussian log-likelihood
_LOG_2PI = math.log(2.0 * math.pi)


def _exp(w: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the rotation vector ``w`` (3,) (Rodrigues; scipy's Rotation
    costs ~30 us a call, and the filter makes several per frame)."""
    angle = math.sqrt(float(w @ w))
    K = _skew(w)
    if angle < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(angle) / angle * K + (1.0 - math.cos(angle)) / angle**2 * K @ K


def _log(R: np.ndarray) -> np.ndarray:
    """(3,) rotation vector of the rotation ``R`` (3, 3); scipy's near a half turn."""
    c = max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    angle = math.acos(c)
    if angle < 1e-6:
        return 0.5 * v
    if angle > math.pi - 1e-3:
        return Rotation.from_matrix(R).as_rotvec()
    return angle / (2.0 * math.sin(angle)) * v


def _skew(a: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix: ``_skew(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _left_jacobian(phi: np.ndarray) -> np.ndarray:
    """(3, 3) left Jacobian of SO(3) at the rotation vector ``phi`` (3,): the translation
    of ``Exp((w, rho) dt)`` is ``J(w dt) rho dt``."""
    angle = float(np.linalg.norm(phi))
    K = _skew(phi)
    if angle < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return (
        np.eye(3)
        + (1.0 - math.cos(angle)) / angle**2 * K
        + (angle - math.sin(angle)) / angle**3 * K @ K
    )


def _lever_arm(q: float, t_mm: np.ndarray) -> np.ndarray:
    """(3, 3) ``q (|t|^2 I - t t^T)``: the density of ``x x t`` for ``x`` white of density
    ``q I`` (a rotation's acceleration about a centre as far as the target's origin)."""
    return q * (t_mm @ t_mm * np.eye(3) - np.outer(t_mm, t_mm))


def _linear_density(cfg: RelativeStateConfig, t_mm: np.ndarray) -> np.ndarray:
    """(3, 3) spectral density of the target origin's linear acceleration, mm^2 / s^3:
    the linear white acceleration plus the lever-arm term of an angular acceleration
    about the camera, ``q_a (|t|^2 I - t t^T)`` (module docstring)."""
    return cfg.linear_accel_psd * np.eye(3) + _lever_arm(cfg.angular_accel_psd, t_mm)


@dataclass
class RelativeStateFilter:
    """The filter (module docstring). ``update(time_s, R, t_mm, covariance)`` per pose,
    ``predict(time_s)`` for a frame without one, ``state_at(time_s)`` for the state at
    any later time without changing the filter (latency compensation)."""

    config: RelativeStateConfig = field(default_factory=RelativeStateConfig)
    _time_s: float | None = None
    _fused_s: float = 0.0  # time of the last pose fused (or started from)
    _R: np.ndarray = field(default_factory=lambda: np.eye(3))
    _t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _w: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _v: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _a: np.ndarray = field(default_factory=lambda: np.zeros(3))  # rad/s^2 (18 states)
    _b: np.ndarray = field(default_factory=lambda: np.zeros(3))  # mm/s^2 (18 states)
    _P: np.ndarray = field(default_factory=lambda: np.eye(12))
    _status: Status = "initialised"
    _d2: float = float("nan")
    _log_likelihood: float = float("nan")  # of the last pose, before the gate
    _rejected: list = field(default_factory=list)

    @property
    def initialised(self) -> bool:
        return self._time_s is not None

    @property
    def log_likelihood(self) -> float:
        """log N(y; 0, S) of the last pose's innovation y under the predicted covariance
        S (before the gate; NaN when the last step fused no pose against a prediction)."""
        return self._log_likelihood

    def reset(self) -> None:
        """Forget everything: the next pose starts the filter again."""
        self._time_s = None
        self._rejected = []

    # -- the model ------------------------------------------------------------------------
    def _propagated(self, dt: float):
        """(R, t, w, v, a, b, P) propagated by dt >= 0 s (module docstring): the nominal
        state in closed form (constant twist) or along the mid-step twist (with the twist's
        acceleration a, b), P through the linearised model."""
        cfg = self.config
        n = cfg.n_states
        w, v, t, a, b = self._w, self._v, self._t, self._a, self._b
        u = v - np.cross(w, t)  # the twist's linear part
        w_mid, u_mid = w + 0.5 * a * dt, u + 0.5 * b * dt
        turn = _exp(w_mid * dt)
        R = turn @ self._R
        t_new = turn @ t + _left_jacobian(w_mid * dt) @ u_mid * dt
        w_new = w + a * dt
        v_new = u + b * dt + np.cross(w_new, t_new)
        # linearised error dynamics d(dx)/dt = A dx + noise of density Qc (n, n), taken at
        # the mid-step state (with the acceleration, v changes by (a x t + b) dt within a
        # step: at the start's state the transition would miss it)
        t_c = 0.5 * (t + t_new)
        v_c = u_mid + np.cross(w_mid, t_c)
        A = np.zeros((n, n))
        A[0:3, 0:3] = _skew(w_mid)
        A[0:3, 6:9] = np.eye(3)
        A[3:6, 9:12] = np.eye(3)
        A[9:12, 6:9] = -_skew(v_c)
        A[9:12, 9:12] = _skew(w_mid)
        Qc = np.zeros((n, n))
        Qc[6:9, 6:9] = cfg.angular_accel_psd * np.eye(3)
        Qc[9:12, 9:12] = _linear_density(cfg, t_c)
        # 18 states (n_states: a jerk density set): dw/dt = a, dv/dt = w x v + a x t + b,
        # da/dt, db/dt white
        jerk_psd = cfg.angular_jerk_psd
        if jerk_psd is not None:
            A[6:9, 12:15] = np.eye(3)
            A[9:12, 12:15] = -_skew(t_c)
            A[9:12, 3:6] = _skew(a)
            A[9:12, 15:18] = np.eye(3)
            Qc[12:15, 12:15] = jerk_psd * np.eye(3)
            Qc[15:18, 15:18] = _lever_arm(jerk_psd * cfg.centre_fraction**2, t_c)
        # Van Loan: expm([[-A, Qc], [0, A^T]] dt) = [[., F^-1 Q], [0, F^T]]
        M = np.zeros((2 * n, 2 * n))
        M[:n, :n], M[:n, n:], M[n:, n:] = -A * dt, Qc * dt, A.T * dt
        E = expm(M)
        F = E[n:, n:].T
        Q = F @ E[:n, n:]
        P = F @ self._P @ F.T + Q
        return R, t_new, w_new, v_new, a.copy(), b.copy(), 0.5 * (P + P.T)

    def _start(
        self,
        time_s: float,
        R: np.ndarray,
        t_mm: np.ndarray,
        cov: np.ndarray,
        before: tuple | None = None,
    ) -> None:
        """Start from a pose (rate and velocity unknown: the initial sigmas), or, with
        ``before`` = (time_s, R, t_mm, cov) of an earlier pose of the same motion, with the
        rate and velocity of the two and their covariance (the difference of two poses
        over their interval, plus the acceleration's spread over it)."""
        cfg = self.config
        self._time_s = self._fused_s = float(time_s)
        self._R, self._t = np.array(R, float), np.array(t_mm, float)
        self._w, self._v = np.zeros(3), np.zeros(3)
        self._a, self._b = np.zeros(3), np.zeros(3)
        self._P = np.zeros((cfg.n_states, cfg.n_states))
        self._P[:6, :6] = cov
        self._P[6:9, 6:9] = math.radians(cfg.initial_rate_sigma_deg_s) ** 2 * np.eye(3)
        self._P[9:12, 9:12] = cfg.initial_velocity_sigma_mm_s**2 * np.eye(3)
        if cfg.n_states == 18:
            var_a = math.radians(cfg.initial_accel_sigma_deg_s2) ** 2
            self._P[12:15, 12:15] = var_a * np.eye(3)
            self._P[15:18, 15:18] = _lever_arm(var_a * cfg.centre_fraction**2, self._t)
        if before is not None and time_s - before[0] > 1e-6:
            dt = float(time_s - before[0])
            x = np.concatenate(
                [_log(self._R @ np.asarray(before[1]).T), self._t - np.asarray(before[2], float)]
            )
            self._w, self._v = x[:3] / dt, x[3:] / dt
            self._P[6:12, 6:12] = (cov + before[3]) / dt**2  # of (x1 - x0) / dt
            self._P[:6, 6:12] = self._P[6:12, :6] = cov / dt  # cov(x1, (x1 - x0) / dt)
            self._P[6:9, 6:9] += cfg.angular_accel_psd * dt / 3 * np.eye(3)
            self._P[9:12, 9:12] += dt / 3 * _linear_density(cfg, self._t)
            if cfg.n_states == 18:  # the two poses give the mean rate over the interval:
                # the rate now differs by a dt / 2, the velocity by (a x t + b) dt / 2
                var_a = math.radians(cfg.initial_accel_sigma_deg_s2) ** 2
                h2 = (dt / 2) ** 2
                self._P[6:9, 6:9] += h2 * var_a * np.eye(3)
                self._P[9:12, 9:12] += h2 * _lever_arm(
                    var_a * (1 + cfg.centre_fraction**2), self._t
                )
                self._P[6:9, 12:15] = self._P[12:15, 6:9] = dt / 2 * var_a * np.eye(3)
        self._rejected = []

    def _advance(self, time_s: float) -> None:
        if self._time_s is None:
            raise RuntimeError("the filter has no state yet: it starts with a pose")
        dt = float(time_s) - self._time_s
        if dt < 0:
            raise ValueError(
                f"time {time_s:.6f} s is before the filter's {self._time_s:.6f} s: "
                "poses must come in time order"
            )
        self._R, self._t, self._w, self._v, self._a, self._b, self._P = self._propagated(dt)
        self._time_s = float(time_s)

    # -- the interface ---------------------------------------------------------------------
    def update(
        self, time_s: float, R: np.ndarray, t_mm: np.ndarray, covariance: np.ndarray
    ) -> RelativeState:
        """Fuse a pose (R (3, 3) R_camera_target, t_mm (3,), covariance (6, 6) rotation
        vector rad then mm, the pipeline's) taken at ``time_s``."""
        cov = np.asarray(covariance, float)
        if cov.shape != (6, 6) or not np.all(np.isfinite(cov)):
            raise ValueError("a pose's covariance must be a finite 6 x 6 matrix")
        # the gap counts from the last pose fused, not from the last prediction: a
        # dropout bridged by predict() on every frame still restarts the filter
        self._log_likelihood = float("nan")
        if not self.initialised or time_s - self._fused_s > self.config.max_gap_s:
            self._start(time_s, R, t_mm, cov)
            self._status, self._d2 = "initialised", float("nan")
            return self.state()
        self._advance(time_s)
        y = np.concatenate(
            [_log(np.asarray(R, float) @ self._R.T), np.asarray(t_mm, float) - self._t]
        )
        S = self._P[:6, :6] + cov
        d2 = float(y @ np.linalg.solve(S, y))
        self._d2 = d2
        self._log_likelihood = -0.5 * (d2 + float(np.linalg.slogdet(S)[1]) + 6 * _LOG_2PI)
        if d2 > self.config.gate_chi2:
            self._rejected.append((float(time_s), np.array(R, float), np.array(t_mm, float), cov))
            if len(self._rejected) >= self.config.reset_after and self._rejected_agree():
                _, R0, t0, c0 = self._rejected[-1]
                before = self._rejected[-2] if len(self._rejected) > 1 else None
                self._start(time_s, R0, t0, c0, before=before)
                self._status = "reset"
                return self.state()
            self._status = "rejected"
            return self.state()
        self._rejected = []
        K = np.linalg.solve(S, self._P[:6, :]).T  # (n, 6) = P H^T S^-1 (S symmetric)
        dx = K @ y
        self._R = _exp(dx[0:3]) @ self._R
        self._t = self._t + dx[3:6]
        self._w = self._w + dx[6:9]
        self._v = self._v + dx[9:12]
        if len(dx) == 18:
            self._a = self._a + dx[12:15]
            self._b = self._b + dx[15:18]
        IKH = np.eye(len(dx))
        IKH[:, :6] -= K
        P = IKH @ self._P @ IKH.T + K @ cov @ K.T  # Joseph form
        self._P = 0.5 * (P + P.T)
        self._fused_s = float(time_s)
        self._status = "updated"
        return self.state()

    def _rejected_agree(self) -> bool:
        """Whether the rejected poses in a row describe one motion: each one within the
        gate of the one before it, with the rate and velocity they imply."""
        poses = self._rejected[-self.config.reset_after :]
        for (t0, R0, p0, c0), (t1, R1, p1, c1) in zip(poses, poses[1:], strict=False):
            cfg, dt = self.config, max(t1 - t0, 1e-3)
            y = np.concatenate([_log(R1 @ R0.T), p1 - p0])
            # the rate and velocity are unknown: the initial sigmas' motion over the
            # interval, and the accelerations', on top of the two poses' own covariances
            turn = (
                cfg.angular_accel_psd * dt**3 / 3
                + (math.radians(cfg.initial_rate_sigma_deg_s) * dt) ** 2
            )
            move = cfg.linear_accel_psd * dt**3 / 3 + (cfg.initial_velocity_sigma_mm_s * dt) ** 2
            S = c0 + c1 + np.diag([turn] * 3 + [move] * 3)
            if float(y @ np.linalg.solve(S, y)) > self.config.gate_chi2:
                return False
        return True

    def step(
        self,
        time_s: float,
        R: np.ndarray | None,
        t_mm: np.ndarray | None,
        covariance: np.ndarray | None,
    ) -> RelativeState | None:
        """One frame as it comes from the pipeline: its pose fused (``update``) when it
        has one, else the state predicted to its time (``predict``); None before the
        first pose. A frame older than the filter's state (a replayed recording that
        started over, a clock reset) restarts it from that frame's pose."""
        if self._time_s is not None and time_s < self._time_s:
            self.reset()
        if R is not None and t_mm is not None and covariance is not None:
            return self.update(time_s, R, t_mm, covariance)
        return self.predict(time_s) if self.initialised else None

    def predict(self, time_s: float) -> RelativeState:
        """Advance to ``time_s`` without a measurement (a frame without a pose)."""
        if not self.initialised:
            raise RuntimeError("the filter has no state yet: it starts with a pose")
        self._advance(time_s)
        self._status = "predicted"
        self._log_likelihood = float("nan")
        return self.state()

    def state_at(self, time_s: float) -> RelativeState:
        """The state predicted to ``time_s`` (>= the last step's time), the filter left as
        it is: the controller's time, ahead of the frame's by the latency."""
        if self._time_s is None:
            raise RuntimeError("the filter has no state yet: it starts with a pose")
        dt = float(time_s) - self._time_s
        if dt < 0:
            raise ValueError(f"time {time_s:.6f} s is before the filter's {self._time_s:.6f} s")
        R, t, w, v, _, _, P = self._propagated(dt)
        return self._state(float(time_s), R, t, w, v, P, "predicted")

    def state(self) -> RelativeState:
        """The state at the last step's time."""
        if not self.initialised:
            raise RuntimeError("the filter has no state yet: it starts with a pose")
        return self._state(self._time_s, self._R, self._t, self._w, self._v, self._P, self._status)

    def _state(self, time_s, R, t, w, v, P, status) -> RelativeState:
        return RelativeState(
            time_s=time_s,
            R=R.copy(),
            t_mm=t.copy(),
            angular_rate_deg_s=np.degrees(w),
            angular_rate_target_deg_s=np.degrees(R.T @ w),
            velocity_mm_s=v.copy(),
            covariance=P[:12, :12].copy(),
            status=status,
            innovation_d2=self._d2,
            n_rejected=len(self._rejected),
        )


def state_error(
    state: RelativeState,
    R_true: np.ndarray,
    t_true_mm: np.ndarray,
    w_true_rad_s: np.ndarray,
    v_true_mm_s: np.ndarray,
) -> np.ndarray:
    """(12,) error of a state against truth in the filter's error-state convention
    (rotation vector of ``R R_true^T`` rad, mm, rad/s, mm/s); ``e @ inv(P) @ e`` is its
    NEES."""
    return np.concatenate(
        [
            _log(state.R @ np.asarray(R_true).T),
            state.t_mm - t_true_mm,
            np.radians(state.angular_rate_deg_s) - w_true_rad_s,
            state.velocity_mm_s - v_true_mm_s,
        ]
    )
