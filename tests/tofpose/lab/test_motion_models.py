"""The two-model relative state (``tofpose.lab.motion_models``) against known motion:
poses drawn around a true trajectory with the covariance they are reported with."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.lab.motion_models import TwoModelRelativeState
from tofpose.lab.relative_state import RelativeStateConfig, RelativeStateFilter

#: a pose's sigmas: 0.1 deg per rotation axis, 0.5 mm lateral, 2 mm along the view
SIGMA = np.array([math.radians(0.1)] * 3 + [0.5, 0.5, 2.0])


def _poses(rate_of_time, seconds=12.0, hz=10.0, seed=0):
    """(time s, R, t mm, covariance, true camera-frame rate rad/s (3,)) per frame: the
    target 5 m away turning about its own centre at ``rate_of_time(t)`` (3,) rad/s
    (camera frame), each pose measured with ``SIGMA``."""
    rng = np.random.default_rng(seed)
    cov = np.diag(SIGMA**2)
    R = np.eye(3)
    t_mm = np.array([100.0, -50.0, 5000.0])
    out, dt = [], 1.0 / hz
    for k in range(int(seconds * hz)):
        w = rate_of_time(k * dt)
        noise = rng.normal(0.0, SIGMA)
        R_meas = Rotation.from_rotvec(noise[:3]).as_matrix() @ R
        out.append((k * dt, R_meas, t_mm + noise[3:], cov, w))
        R = Rotation.from_rotvec(w * dt).as_matrix() @ R
    return out


def _rate_rms(filt, poses, after_s=4.0):
    """RMS over the frames after ``after_s`` of |w_est - w_true| (rad/s)."""
    errs = []
    for time_s, R, t_mm, cov, w in poses:
        s = filt.step(time_s, R, t_mm, cov)
        if time_s >= after_s:
            errs.append(np.radians(s.angular_rate_deg_s) - w)
    return float(np.sqrt(np.mean(np.sum(np.square(errs), axis=1))))


@pytest.mark.parametrize("seed", range(3))
def test_a_constant_tumble_is_read_by_the_quiet_model(seed):
    """5 deg/s about a tilted axis: the two-model rate is at least twice as close as the
    manoeuvring model's alone, within 10 % of the rate, and the quiet model is the one
    selected at the end."""
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    w = math.radians(5.0) * axis
    poses = _poses(lambda _t: w, seed=seed)
    two = TwoModelRelativeState()
    moving = RelativeStateFilter(RelativeStateConfig.constant_acceleration())
    two_rms, moving_rms = _rate_rms(two, poses), _rate_rms(moving, poses)
    assert two_rms < 0.5 * moving_rms
    assert two_rms < 0.1 * math.radians(5.0)
    assert two.selected == 0


@pytest.mark.parametrize("seed", range(3))
def test_a_slew_is_followed_as_the_manoeuvring_model_follows_it(seed):
    """A yaw sine of 5 deg and 4 s (peak 7.9 deg/s, the turntable's): the two-model rate
    error is within 50 % of the manoeuvring model's alone, and far below the quiet
    model's (which lags the slew)."""
    amp, period = math.radians(5.0), 4.0
    poses = _poses(
        lambda t: np.array(
            [0.0, amp * 2 * math.pi / period * math.cos(2 * math.pi * t / period), 0.0]
        ),
        seed=seed,
    )
    two = _rate_rms(TwoModelRelativeState(), poses)
    moving = _rate_rms(RelativeStateFilter(RelativeStateConfig.constant_acceleration()), poses)
    quiet = _rate_rms(RelativeStateFilter(TwoModelRelativeState().models[0]), poses)
    assert two < 1.5 * moving
    assert two < 0.7 * quiet


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="two motion models"):
        TwoModelRelativeState(models=(RelativeStateConfig(),))
    with pytest.raises(ValueError, match="stay_probability"):
        TwoModelRelativeState(stay_probability=1.0)
