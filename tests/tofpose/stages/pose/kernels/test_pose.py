"""Pose kernels against NumPy and against ``tofpose.stages.pose.reference.pose`` (the statement of
§5)."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.pose.kernels.pose import facing_cosine
from tofpose.stages.pose.records import Reflectors


def test_facing_cosine_is_the_cosine_of_the_view_angle():
    """Against ``tofpose.stages.pose.reference.pose.facing_cosine``."""
    from tofpose.stages.pose.reference.pose import facing_cosine as reference

    rng = np.random.default_rng(2)
    centroid = rng.normal(0, 100, 3)
    for _ in range(200):
        R = rotation_from_euler_deg(*rng.uniform(-180, 180, 3))
        t = rng.normal(0, 500, 3) + [0, 0, 3000]
        assert abs(facing_cosine(R, t, centroid) - reference(R, t, centroid)) < 1e-14


def _scene(seed, m=8, range_mm=5000.0, sb_rad=2e-4, sr_mm=6.0):
    """The paper target's first m reflectors at a random attitude and ``range_mm``, seen
    with bearing and range errors of the given sigmas: x, e, rho, sr, sb, R, t."""
    from scipy.spatial.transform import Rotation

    from tofpose.core.catalog import paper_target

    rng = np.random.default_rng(seed)
    x = paper_target().positions_mm[:m]
    R = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
    t = np.array([rng.uniform(-300, 300), rng.uniform(-300, 300), range_mm])
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e = y / rho[:, None] + rng.normal(0, sb_rad, y.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rho = rho + rng.normal(0, sr_mm, m)
    sr = rng.uniform(0.5, 2.0, m) * sr_mm
    sb = rng.uniform(0.5, 2.0, m) * sb_rad
    return x, e, rho, sr, sb, R, t


@pytest.mark.parametrize("seed", range(8))
def test_absolute_orientation_is_the_svd_solution_of_eqs_40_to_50(seed):
    """Horn's quaternion form against the SVD of Eq. 45 (``tofpose.reference``), weighted,
    on noisy points (where the two could differ) and on a mirror-prone flat pattern."""
    from tofpose.stages.pose.kernels.pose import absolute_orientation
    from tofpose.stages.pose.reference.pose import absolute_orientation as reference

    x, e, rho, _, _, _, _ = _scene(seed)
    y = e * rho[:, None]
    w = np.random.default_rng(seed).uniform(0.2, 3.0, len(x))
    R, t = absolute_orientation(x, y, w)
    R_ref, t_ref = reference(x, y, w)
    np.testing.assert_allclose(R, R_ref, atol=1e-10)
    np.testing.assert_allclose(t, t_ref, atol=1e-7)


@pytest.mark.parametrize("seed", range(6))
def test_ml_refinement_reaches_scipys_least_squares_optimum(seed):
    """Gauss-Newton (compiled) against SciPy's Levenberg-Marquardt on the same whitened
    residuals stated independently (tangent bases by the SVD, Jacobian by central
    differences): the same pose (to a thousandth of its sigma: the two stop at different
    points of the last step), chi^2 and covariance."""
    from tofpose.stages.pose.kernels.pose import absolute_orientation, ml_refine
    from tofpose.stages.pose.reference import pose as reference

    x, e, rho, sr, sb, _, _ = _scene(seed, m=5 + seed % 4)
    R0, t0 = absolute_orientation(x, e * rho[:, None], 1.0 / (sr**2 + (rho * sb) ** 2))
    refl = Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb)
    R, t, cov, chi2, _, _ = ml_refine(refl, R0, t0, 30, 1e-12, 0.0)
    R_ref, t_ref, cov_ref, chi2_ref = reference.ml_refine(refl, R0, t0)
    from scipy.spatial.transform import Rotation

    d = np.concatenate([Rotation.from_matrix(R @ R_ref.T).as_rotvec(), t - t_ref])
    assert d @ np.linalg.solve(cov_ref, d) < 1e-6  # the same optimum to 1e-3 sigma
    assert chi2 == pytest.approx(chi2_ref, rel=1e-6)
    np.testing.assert_allclose(cov, cov_ref, rtol=1e-4, atol=1e-9 * np.abs(cov_ref).max())


@pytest.mark.parametrize("seed", range(4))
def test_line_of_sight_iteration_is_eqs_51_and_52(seed):
    from tofpose.stages.pose.kernels.pose import absolute_orientation, line_of_sight
    from tofpose.stages.pose.reference import pose as reference

    x, e, rho, _, _, _, _ = _scene(seed)
    w = np.ones(len(x))
    R0, t0 = absolute_orientation(x, e * rho[:, None], w)
    R, t, its = line_of_sight(x, e, R0, t0, w, 1e-6, 200)
    R_ref, t_ref, its_ref = reference.line_of_sight(x, e, R0, t0, w, 1e-6, 200)
    assert its == its_ref
    np.testing.assert_allclose(R, R_ref, atol=1e-9)
    np.testing.assert_allclose(t, t_ref, atol=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_leave_one_out_spread_and_envelope_equal_the_reference(seed):
    from tofpose.stages.pose.kernels.pose import (
        covariance_envelope,
        leave_one_out_spread,
        ml_refine,
    )
    from tofpose.stages.pose.reference import pose as reference

    x, e, rho, sr, sb, R, t = _scene(seed, m=4 + seed % 5, range_mm=7000.0)
    refl = Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb)
    R, t, cov, _, _, _ = ml_refine(refl, R, t, 30, 1e-12, 0.0)
    spread = leave_one_out_spread(refl, R, t)
    want = reference.leave_one_out_spread(refl, R, t)
    np.testing.assert_allclose(spread, want, rtol=1e-5, atol=1e-7 * np.abs(want).max())
    np.testing.assert_allclose(
        covariance_envelope(cov, spread),
        reference.covariance_envelope(cov, spread),
        rtol=1e-9,
        atol=1e-12 * np.abs(cov).max(),
    )


@pytest.mark.parametrize("seed", range(4))
def test_concluding_covariances_are_the_three_kernels_and_the_reference(seed):
    """One call, one Jacobian: exactly (bit for bit) what ``range_bias_covariance``,
    ``class_scale_covariance`` and ``leave_one_out_spread`` give one by one, zeros for a
    term that is off, and the reference statement's values to its tolerance."""
    from tofpose.stages.pose.kernels.pose import (
        class_scale_covariance,
        concluding_covariances,
        leave_one_out_spread,
        ml_refine,
        range_bias_covariance,
    )
    from tofpose.stages.pose.records import CovarianceTerms
    from tofpose.stages.pose.reference import pose as reference

    m = 4 + seed
    x, e, rho, sr, sb, R, t = _scene(seed, m=m, range_mm=4000.0)
    refl = Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb)
    R, t, *_ = ml_refine(refl, R, t, 30, 1e-12, 0.0)
    group = np.arange(m, dtype=np.int64) % 2
    terms = CovarianceTerms(
        bias_sigma_mm=12.0,
        by_size=True,
        group=group,
        n_groups=2,
        bias_rad=0.05 / 325.0,
        common_scale_sigma=0.002,
        leave_one_out=True,
    )
    got = concluding_covariances(refl, R, t, terms)
    assert np.array_equal(got.range_bias, range_bias_covariance(refl, R, t, 12.0))
    assert np.array_equal(
        got.by_size, class_scale_covariance(refl, R, t, group, 2, 0.05 / 325.0, 0.002)
    )
    assert np.array_equal(got.spread, leave_one_out_spread(refl, R, t))
    assert np.abs(got.range_bias).max() > 0 and np.abs(got.spread).max() > 0
    want = reference.concluding_covariances(refl, R, t, terms)
    for name in ("range_bias", "by_size", "spread"):
        a, b = getattr(got, name), getattr(want, name)
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7 * np.abs(b).max())
    off = concluding_covariances(
        refl, R, t, terms._replace(bias_sigma_mm=0.0, by_size=False, leave_one_out=False)
    )
    for name in ("range_bias", "by_size", "spread"):
        assert not getattr(off, name).any()
