"""Bench calibration recovers a known camera mount and target placement."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.calibration.bench import BenchObservation, calibrate_bench, mean_pose
from tofpose.core.geometry import RigidTransform, rotation_angle_deg
from tofpose.lab.kinematics import camera_target
from tofpose.sim.bench import R_FACING

NOMINAL_X = RigidTransform.identity()
NOMINAL_Y = RigidTransform(R_FACING, np.array([0.0, 0.0, 15000.0]))
TRUE_X = NOMINAL_X.compose(RigidTransform.from_euler_deg(0.2, -0.25, 0.1, (1.5, -1.0, 0.5)))
TRUE_Y = NOMINAL_Y.compose(RigidTransform.from_euler_deg(-0.15, 0.1, 0.3, (3.0, -2.0, 4.0)))


def _set_points(rails=(11000.0, 12500.0), a=8.0):
    from backend.services.campaigns.campaign_plan import calibration  # the generator the lab uses

    return calibration(rails_mm=list(rails), amplitude_deg=a)


def _observe(setpoints, sigma_mm, sigma_deg, seed=0, noisy=True):
    rng = np.random.default_rng(seed)
    obs = []
    for sp in setpoints:
        T = camera_target(sp, TRUE_X, TRUE_Y)
        if noisy:
            T = T.compose(
                RigidTransform.from_euler_deg(
                    *rng.normal(0, sigma_deg, 3), rng.normal(0, sigma_mm, 3)
                )
            )
        obs.append(BenchObservation(sp, T, sigma_mm, sigma_deg))
    return obs


def _errors(cal):
    return (
        rotation_angle_deg(cal.T_inner_camera.R, TRUE_X.R),
        float(np.linalg.norm(cal.T_inner_camera.t_mm - TRUE_X.t_mm)),
        rotation_angle_deg(cal.T_lab_target.R, TRUE_Y.R),
        float(np.linalg.norm(cal.T_lab_target.t_mm - TRUE_Y.t_mm)),
    )


def test_noise_free_observations_give_the_exact_mount_and_placement():
    cal = calibrate_bench(_observe(_set_points(), 0.1, 0.01, noisy=False), NOMINAL_X, NOMINAL_Y)
    rx, tx, ry, ty = _errors(cal)
    assert rx < 1e-5 and tx < 1e-5 and ry < 1e-5 and ty < 1e-5
    assert cal.residual_mm.max() < 1e-5


def test_realistic_noise_recovers_within_0_02_deg_and_0_5_mm_with_honest_sigmas():
    """Per set-point means of ~20 frames at 2.5-4 m: 0.1 mm and 0.01 deg of noise."""
    cal = calibrate_bench(_observe(_set_points(), 0.1, 0.01, seed=4), NOMINAL_X, NOMINAL_Y)
    rx, tx, ry, ty = _errors(cal)
    assert rx < 0.02 and ry < 0.02, (rx, ry)
    assert tx < 0.5 and ty < 0.5, (tx, ty)
    # the reported 1-sigma covers the error (4 sigma, per group, as a norm bound)
    s = cal.sigmas
    assert tx < 4 * np.linalg.norm(s[3:6]) and ty < 4 * np.linalg.norm(s[9:12])
    assert 0.3 < cal.chi2_per_dof < 3.0


def test_too_few_or_degenerate_observations_are_refused():
    obs = _observe(_set_points(), 0.1, 0.01)
    with pytest.raises(ValueError, match="at least 3 observations"):
        calibrate_bench(obs[:2], NOMINAL_X, NOMINAL_Y)
    yaw_only = _observe([{"yaw": y, "rail": 12000.0} for y in (-8, 0, 8)], 0.1, 0.01)
    with pytest.raises(ValueError, match="fewer than two axes"):
        calibrate_bench(yaw_only, NOMINAL_X, NOMINAL_Y)


def test_mean_pose_of_identical_poses_is_that_pose():
    T = RigidTransform.from_euler_deg(1, 2, 3, (4, 5, 6))
    m = mean_pose([T, T, T])
    np.testing.assert_allclose(m.R, T.R, atol=1e-12)
    np.testing.assert_allclose(m.t_mm, T.t_mm)
