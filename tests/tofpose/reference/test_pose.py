"""The reference statement of §5 against known truth: the test oracle must itself be
right."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from tofpose.catalog import paper_target
from tofpose.reference import pose as reference


def _truth(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
    return R, np.array([120.0, -80.0, 4000.0])


def test_absolute_orientation_recovers_an_exact_pose_and_agrees_with_scipy():
    x = paper_target().positions_mm
    R, t = _truth(1)
    y = x @ R.T + t
    R_est, t_est = reference.absolute_orientation(x, y, np.linspace(1, 2, len(x)))
    np.testing.assert_allclose(R_est, R, atol=1e-12)
    np.testing.assert_allclose(t_est, t, atol=1e-8)
    noisy = y + np.random.default_rng(2).normal(0, 5.0, y.shape)
    R_est, t_est = reference.absolute_orientation(x, noisy, np.ones(len(x)))
    rot, _ = Rotation.align_vectors(noisy - noisy.mean(0), x - x.mean(0))
    np.testing.assert_allclose(R_est, rot.as_matrix(), atol=1e-10)


def test_ml_refine_recovers_the_pose_of_noiseless_measurements_with_zero_chi2():
    x = paper_target().positions_mm
    R, t = _truth(3)
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e = y / rho[:, None]
    sr, sb = np.full(8, 5.0), np.full(8, 3e-4)
    R0 = Rotation.from_rotvec([0.02, -0.01, 0.03]).as_matrix() @ R
    R_est, t_est, cov, chi2 = reference.ml_refine(x, e, rho, R0, t + [5.0, -3.0, 20.0], sr, sb)
    np.testing.assert_allclose(R_est, R, atol=1e-9)
    np.testing.assert_allclose(t_est, t, atol=1e-6)
    assert chi2 < 1e-12
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_whitened_residuals_count_sigmas():
    """A reflector 10 mm long along its line of sight (sigma 5 mm): range residual 2;
    one 2 mm across it at its range with a bearing sigma of 1e-3 rad: lateral norm
    2 / (rho 1e-3)."""
    x = paper_target().positions_mm
    R, t = _truth(4)
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e = y / rho[:, None]
    rho_m = rho.copy()
    rho_m[0] -= 10.0  # the point is 10 mm beyond the measured range: residual +2
    side = np.cross(e[1], [0.0, 0.0, 1.0])
    y1 = y[1] + 2.0 * side / np.linalg.norm(side)
    e_m = e.copy()
    e_m[1] = y1 / np.linalg.norm(y1)
    r = reference.whitened_residuals(x, e_m, rho_m, R, t, np.full(8, 5.0), np.full(8, 1e-3))
    assert abs(r[2] - 2.0) < 1e-9
    assert abs(np.linalg.norm(r[3:5]) - 2.0 / (rho[1] * 1e-3)) < 1e-3 * 2.0 / (rho[1] * 1e-3)
    assert np.abs(r[6:]).max() < 1e-9
