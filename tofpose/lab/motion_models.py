"""The relative state under two motion models at once, reported from the one the recent
poses favour (ours): a target that tumbles freely turns at a constant rate, a turntable
slews with accelerations, and one filter tuned for either is poor at the other.

``RelativeStateFilter`` with a fixed process noise must choose: the manoeuvring model
(``RelativeStateConfig.constant_acceleration()``, tuned for the turntable's slews)
follows a slew but lets the rate wander with every pose's noise; on a constant tumble of
3-8 deg/s at 3-8 m, 10 poses a second, its rate is off by 30-45 % RMS on our simulator,
where a constant twist with a small acceleration density is off by 4-9 %, and lags a
slew. So both run on every pose, side by side, and their probabilities follow the
poses' innovation likelihoods with the standard recursion of a multiple-model filter
(the IMM's model probabilities; each filter keeps its own state, none is mixed into
the other, since the two states differ in size): with ``p`` the chance of staying in a
model between poses, ``mu_j <- L_j sum_i p_ij mu_i`` normalised, ``L_j`` the Gaussian
likelihood of the pose's innovation under model j. The state reported is the IMM's
combined output: the rate, velocity and position are the probability-weighted means of
the two models' (the attitude the more probable model's), and the covariance (12, 12)
the mixture's, each model's covariance plus the spread of its mean about the combined
one, so that a pose where the models disagree says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from tofpose.lab.relative_state import RelativeState, RelativeStateConfig, RelativeStateFilter

#: the quiet model: a constant twist with white angular acceleration of (0.3 deg)^2 / s^3
#: and linear of (10 mm)^2 / s^3 (a free tumble, a drift)
QUIET = RelativeStateConfig(angular_accel_psd=math.radians(0.3) ** 2, linear_accel_psd=10.0**2)
#: the chance that the motion keeps its model from one pose to the next
STAY_PROBABILITY = 0.99
#: the smallest probability a model keeps (so that it can come back at once)
MIN_PROBABILITY = 1e-4


@dataclass
class TwoModelRelativeState:
    """``step(time_s, R, t_mm, covariance)`` as ``RelativeStateFilter.step``, reporting the
    state of the model the recent poses favour (module docstring). ``models`` : the
    configurations (quiet first); ``probabilities`` (2,) after the last pose;
    ``selected`` : the index of the model reported."""

    models: tuple[RelativeStateConfig, ...] = (QUIET, RelativeStateConfig.constant_acceleration())
    stay_probability: float = STAY_PROBABILITY
    _filters: list[RelativeStateFilter] = field(default_factory=list)
    probabilities: np.ndarray = field(default_factory=lambda: np.array([0.5, 0.5]))

    def __post_init__(self) -> None:
        if len(self.models) != 2:
            raise ValueError(f"two motion models are compared, got {len(self.models)}")
        if not 0.0 < self.stay_probability < 1.0:
            raise ValueError(f"stay_probability must be in (0, 1), got {self.stay_probability}")
        self._filters = [RelativeStateFilter(m) for m in self.models]
        self.probabilities = np.array([0.5, 0.5])

    @property
    def selected(self) -> int:
        return int(np.argmax(self.probabilities))

    @property
    def initialised(self) -> bool:
        """Whether both models have a state (after the first pose)."""
        return all(f.initialised for f in self._filters)

    def state_at(self, time_s: float) -> RelativeState:
        """The combined state predicted to ``time_s`` (>= the last step's time), the
        filters left as they are: each model's prediction, with the probabilities one
        switch ahead (``combined``)."""
        p = self.stay_probability
        mu = np.array([[p, 1.0 - p], [1.0 - p, p]]).T @ self.probabilities
        states = [f.state_at(time_s) for f in self._filters]
        return combined(states, mu, int(np.argmax(mu)))

    def reset(self) -> None:
        for f in self._filters:
            f.reset()
        self.probabilities = np.array([0.5, 0.5])

    def step(
        self,
        time_s: float,
        R: np.ndarray | None,
        t_mm: np.ndarray | None,
        covariance: np.ndarray | None,
    ) -> RelativeState | None:
        """One frame (its pose, or None without one) through both models; the favoured
        model's state, or None before the first pose."""
        states = [f.step(time_s, R, t_mm, covariance) for f in self._filters]
        logs = np.array([f.log_likelihood for f in self._filters])
        if np.all(np.isfinite(logs)):
            p = self.stay_probability
            switch = np.array([[p, 1.0 - p], [1.0 - p, p]])
            prior = switch.T @ self.probabilities
            post = np.log(prior) + logs - logs.max()
            mu = np.exp(post - post.max())
            mu = np.maximum(mu / mu.sum(), MIN_PROBABILITY)
            self.probabilities = mu / mu.sum()
        quiet, moving = states
        if quiet is None or moving is None:
            return None
        return combined([quiet, moving], self.probabilities, self.selected)


def combined(states: list[RelativeState], mu: np.ndarray, selected: int) -> RelativeState:
    """The IMM output of two models' states with probabilities ``mu`` (2,): t, w, v the
    weighted means, the covariance (12, 12) ``sum mu_j (P_j + d_j d_j^T)`` over the
    common error state (d_j the model's mean minus the combined one; the attitude
    component taken from the ``selected`` model, whose R is reported)."""
    ref = states[selected]
    t = sum(m * s.t_mm for m, s in zip(mu, states, strict=True))
    w = sum(m * s.angular_rate_deg_s for m, s in zip(mu, states, strict=True))
    v = sum(m * s.velocity_mm_s for m, s in zip(mu, states, strict=True))
    cov = np.zeros((12, 12))
    for m, s in zip(mu, states, strict=True):
        d = np.concatenate(
            [
                np.zeros(3),
                s.t_mm - t,
                np.radians(s.angular_rate_deg_s - w),
                s.velocity_mm_s - v,
            ]
        )
        cov += m * (s.covariance[:12, :12] + np.outer(d, d))
    rate_target = ref.R.T @ np.radians(w)
    return replace(
        ref,
        t_mm=t,
        angular_rate_deg_s=w,
        angular_rate_target_deg_s=np.degrees(rate_target),
        velocity_mm_s=v,
        covariance=cov,
    )
