"""The small-matrix loops of §5 against NumPy's LAPACK: Horn's rotation against the SVD
of Eq. 49, Cholesky against ``solve`` and ``inv``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.core.kernels import small_matrices as sm
from tofpose.stages.pose.kernels.pose import absolute_orientation


def _kabsch(x, y, w):
    """Eqs. 40-50 with NumPy's SVD (the form the compiled loops replaced)."""
    ws = w / w.sum()
    xc, yc = x - ws @ x, y - ws @ y
    U, _, Vt = np.linalg.svd((xc * w[:, None]).T @ yc)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, ws @ y - R @ (ws @ x)


@pytest.mark.parametrize("shape", ["general", "planar", "three points"])
def test_svd_pose_is_the_svds_absolute_orientation(shape):
    """Random rotations (every quarter of the sphere), weights and noise; the target's
    nearly planar pattern (where the SVD needs its determinant fix) and three points."""
    rng = np.random.default_rng(3)
    for trial in range(300):
        m = 3 if shape == "three points" else int(rng.integers(4, 12))
        x = rng.normal(0.0, 200.0, (m, 3))
        if shape == "planar":
            x[:, 2] = rng.normal(0.0, 1e-3, m)
        R_true = Rotation.random(random_state=trial).as_matrix()
        y = x @ R_true.T + rng.normal(0.0, 1000.0, 3) + rng.normal(0.0, 0.5, (m, 3))
        w = rng.uniform(0.1, 2.0, m)
        R, t = absolute_orientation(x, y, w)
        R_ref, t_ref = _kabsch(x, y, w)
        np.testing.assert_allclose(R, R_ref, atol=1e-11)
        np.testing.assert_allclose(t, t_ref, atol=1e-8)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


def test_rotation_from_correlation_recovers_an_exact_rotation():
    """Noise-free points: the rotation itself, including half turns (quaternion w = 0)."""
    rng = np.random.default_rng(4)
    x = rng.normal(0.0, 100.0, (6, 3))
    xc = x - x.mean(axis=0)
    for R_true in [
        np.diag([1.0, -1.0, -1.0]),
        np.diag([-1.0, -1.0, 1.0]),
        np.eye(3),
        Rotation.from_rotvec([0.3, -2.0, 1.1]).as_matrix(),
    ]:
        S = xc.T @ (xc @ R_true.T)
        np.testing.assert_allclose(sm.rotation_from_correlation(S), R_true, atol=1e-12)


def test_cholesky_solves_and_inverts_the_normal_equations():
    rng = np.random.default_rng(5)
    for m in (6, 9, 24):
        J = rng.normal(size=(m, 6)) * rng.uniform(0.01, 100.0, 6)  # badly scaled columns
        r = rng.normal(size=m)
        H = sm.gram(J)
        np.testing.assert_allclose(H, J.T @ J, rtol=1e-13, atol=0)
        np.testing.assert_allclose(sm.transposed_times(J, r), J.T @ r, rtol=1e-12, atol=1e-12)
        L, ok = sm.cholesky(H)
        assert ok
        np.testing.assert_allclose(
            sm.cholesky_solve(L, J.T @ r), np.linalg.solve(H, J.T @ r), rtol=1e-9
        )
        inv = sm.cholesky_inverse(L)
        np.testing.assert_allclose(inv, np.linalg.inv(H), rtol=1e-9, atol=1e-15)
        assert np.array_equal(inv, inv.T)


def test_cholesky_refuses_singular_normal_equations():
    """Two points cannot fix the six pose parameters: J^T J is singular, and a NaN in
    the Jacobian makes it unusable; both are reported, not solved."""
    J = np.zeros((6, 6))
    J[:, :3] = np.random.default_rng(6).normal(size=(6, 3))
    assert not sm.cholesky(sm.gram(J))[1]
    H = np.eye(6)
    H[2, 2] = np.nan
    assert not sm.cholesky(H)[1]


def test_matmul3_is_the_matrix_product():
    rng = np.random.default_rng(7)
    A, B = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    np.testing.assert_allclose(sm.matmul3(A, B), A @ B, rtol=1e-14, atol=1e-15)
