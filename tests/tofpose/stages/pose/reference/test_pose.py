"""The reference statement of §5 (``tofpose.stages.pose.reference.pose``) against known truth (the
test oracle must itself be right) and against the compiled fit
(``tofpose.stages.pose.kernels.pose``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.core.catalog import paper_target
from tofpose.core.records import FitSettings
from tofpose.stages.pose import constants
from tofpose.stages.pose.kernels import pose as kernel
from tofpose.stages.pose.records import NO_OFFSET, RangeOffsetPrior, Reflectors
from tofpose.stages.pose.reference import pose as reference


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
    refl = Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb)
    R_est, t_est, cov, chi2 = reference.ml_refine(refl, R0, t + [5.0, -3.0, 20.0])
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
    refl = Reflectors(x=x, e=e_m, rho=rho_m, sr=np.full(8, 5.0), sb=np.full(8, 1e-3))
    r = reference.whitened_residuals(refl, R, t)
    assert abs(r[2] - 2.0) < 1e-9
    assert abs(np.linalg.norm(r[3:5]) - 2.0 / (rho[1] * 1e-3)) < 1e-3 * 2.0 / (rho[1] * 1e-3)
    assert np.abs(r[6:]).max() < 1e-9


# -- the reference fit (tofpose.stages.pose.reference.pose) against the compiled one and truth
# -------

#: the modes of ``fit_pose`` (the kernels' codes)
MODES = {"none": constants.REFINE_NONE, "ml": constants.REFINE_ML, "los": constants.REFINE_LOS}
#: the pose sigma within which the SciPy optimum equals the kernel's Gauss-Newton pose
OPTIMISER_SIGMA = 1e-3
#: ... and within which the same arithmetic (SVD vs Horn's closed form) gives the same pose
EXACT_SIGMA = 1e-8


def _scene(seed, m=8, range_mm=5000.0, sb_rad=2e-4, sr_mm=6.0, noise=1.0):
    """The paper target's first m reflectors at a random attitude and ``range_mm``,
    measured with errors of ``noise`` times the stated sigmas (which vary by reflector):
    x, e, rho, y, sr, sb, R, t."""
    rng = np.random.default_rng(seed)
    x = paper_target().positions_mm[:m]
    R = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
    t = np.array([rng.uniform(-300, 300), rng.uniform(-300, 300), range_mm])
    sr = rng.uniform(0.5, 2.0, m) * sr_mm
    sb = rng.uniform(0.5, 2.0, m) * sb_rad
    p = x @ R.T + t
    rho = np.linalg.norm(p, axis=1)
    e = p / rho[:, None] + noise * sb[:, None] * rng.normal(0, 1, p.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rho = rho + noise * sr * rng.normal(0, 1, m)
    return x, e, rho, e * rho[:, None], sr, sb, R, t


def _sigmas(R, t, R_ref, t_ref, cov):
    """The distance between two poses in sigmas of ``cov`` (rotation vector, then mm)."""
    d = np.concatenate((Rotation.from_matrix(R @ R_ref.T).as_rotvec(), t - t_ref))
    return float(np.sqrt(d @ np.linalg.solve(cov, d)))


def _settings(mode, reject=True, adapt=True, min_matches=3):
    return FitSettings(
        refinement=MODES[mode],
        los_tolerance=0.002,
        step_sigma2=1e-8,
        correct_perspective_bias=True,
        mixed_pixel_radius_px=4.0,
        adapt_range_sigma=adapt,
        max_systematic_range_sigma_mm=25.0,
        max_systematic_centroid_sigma_px=0.5,
        reject_outliers=reject,
        min_matches=min_matches,
        outlier_sigma=6.0,
        outlier_chi2_per_dof=4.0,
    )


def _refl(x, e, rho, sr, sb):
    return Reflectors(x=x, e=e, rho=rho, sr=sr, sb=sb)


def test_small_rules_equal_the_kernels():
    """facing_cosine, reflector_norms, mean_bearing, pattern_scale_sigma,
    scale_directions (in the kernel's tangent bases) and point_residuals_mm: the same
    arithmetic, equal to 1e-12."""
    for seed in range(20):
        x, e, rho, y, sr, sb, R, t = _scene(seed, m=4 + seed % 5)
        centroid = np.random.default_rng(seed).normal(0, 100, 3)
        assert reference.facing_cosine(R, t, centroid) == pytest.approx(
            kernel.facing_cosine(R, t, centroid), abs=1e-14
        )
        r = np.random.default_rng(seed).normal(0, 3, 3 * len(x))
        np.testing.assert_allclose(
            reference.reflector_norms(r), kernel.reflector_norms(r), rtol=1e-14
        )
        np.testing.assert_allclose(reference.mean_bearing(e), kernel.mean_bearing(e), atol=1e-15)
        prior = RangeOffsetPrior(15.0, 0.002 * (seed % 2), 1e-4 * (seed % 3))
        s_ref, mean_ref = reference.pattern_scale_sigma(e, prior)
        s, mean = kernel.pattern_scale_sigma(e, prior)
        assert s_ref == pytest.approx(s, rel=1e-12, abs=1e-18)
        np.testing.assert_allclose(mean_ref, mean, atol=1e-15)
        B = kernel.tangent_bases(e)
        np.testing.assert_allclose(
            reference.scale_directions(e, B, mean), kernel.scale_directions(e, B, mean), atol=1e-15
        )
        got, rms = reference.point_residuals_mm(x, y, R, t)
        want, want_rms = kernel.point_residuals_mm(x, y, R, t)
        np.testing.assert_allclose(got, want, rtol=1e-12)
        assert rms == pytest.approx(want_rms, rel=1e-12)


def test_facing_cosine_is_one_face_on_and_negative_facing_away():
    R = np.diag([1.0, -1.0, -1.0])  # the plate's normal towards the camera
    assert reference.facing_cosine(R, np.array([0.0, 0.0, 3000.0]), np.zeros(3)) == 1.0
    assert reference.facing_cosine(np.eye(3), np.array([0.0, 0.0, 3000.0]), np.zeros(3)) == -1.0


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed", range(4))
def test_fit_pose_equals_the_kernel(mode, seed):
    """fit_pose in each refinement mode. none and los: the same arithmetic, the pose to
    ``EXACT_SIGMA``, iterations and weights equal, chi^2 to 1e-9; ml: SciPy's optimum for
    the kernel's Gauss-Newton, the pose to ``OPTIMISER_SIGMA`` (1e-3 sigma), chi^2 to
    1e-6. The covariance to 1e-5 (the reference's Jacobian is by central differences)."""
    x, e, rho, y, sr, sb, _, _ = _scene(seed, m=5 + seed)
    got = reference.fit_pose(_refl(x, e, rho, sr, sb), _settings(mode))
    want = kernel.fit_pose(_refl(x, e, rho, sr, sb), _settings(mode))
    tol = OPTIMISER_SIGMA if mode == "ml" else EXACT_SIGMA
    assert _sigmas(got.R, got.t, want.R, want.t, want.covariance) < tol
    if mode != "ml":
        assert got.iterations == want.iterations
    atol = 1e-9 * np.abs(want.covariance).max()
    np.testing.assert_allclose(got.covariance, want.covariance, rtol=1e-5, atol=atol)
    assert got.chi2 == pytest.approx(want.chi2, rel=1e-6 if mode == "ml" else 1e-9)
    np.testing.assert_allclose(got.norms, want.norms, rtol=1e-5 if mode == "ml" else 1e-9)
    np.testing.assert_array_equal(got.sr, want.sr)
    np.testing.assert_array_equal(got.sb, want.sb)


def test_fit_pose_of_noiseless_measurements_is_the_true_pose_with_zero_chi2():
    for mode in MODES:
        x, e, rho, y, sr, sb, R, t = _scene(7, noise=0.0)
        fit = reference.fit_pose(
            _refl(x, e, rho, sr, sb), _settings(mode)._replace(los_tolerance=1e-6)
        )
        assert _sigmas(fit.R, fit.t, R, t, fit.covariance) < 1e-6
        assert fit.chi2 < 1e-12 and fit.norms.max() < 1e-6


def test_median_constants_are_the_chi2_medians():
    import scipy.stats

    assert abs(constants.MEDIAN_CHI2_1DOF - scipy.stats.chi2(1).median()) < 1e-5
    assert abs(constants.MEDIAN_CHI2_2DOF - scipy.stats.chi2(2).median()) < 1e-5


@pytest.mark.parametrize("seed", range(6))
def test_systematic_sigmas_equal_the_kernel_and_are_the_rule(seed):
    """Measurements 3x noisier than their sigmas: the excess sigmas are the same grid
    point as the kernel's bisection (to 1e-12), and at them the medians meet chi^2's
    (the rule: just below at the result, above one grid step lower)."""
    x, e, rho, y, sr, sb, R, t = _scene(seed, m=3 + seed, noise=3.0)
    caps = (25.0, 0.5 / 300.0 * (1 + seed % 2))
    got = reference.systematic_sigmas(_refl(x, e, rho, sr, sb), R, t, *caps)
    want = kernel.systematic_sigmas(_refl(x, e, rho, sr, sb), R, t, *caps)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert got[0] > 0 or got[1] > 0
    r = reference.whitened_residuals(_refl(x, e, rho, sr, sb), R, t).reshape(-1, 3)
    for extra, z2, var, target, cap in (
        (got[0], r[:, 2] ** 2, sr**2, 0.45494, caps[0]),
        (got[1], (r[:, :2] ** 2).sum(1), sb**2, 1.38629, caps[1]),
    ):
        if 0 < extra < cap:
            assert np.median(z2 * var / (var + extra**2)) <= target
            lower = extra - cap / 2**16
            assert np.median(z2 * var / (var + lower**2)) > target
    # consistent measurements need no excess
    x, e, rho, y, sr, sb, R, t = _scene(seed, noise=0.0)
    assert reference.systematic_sigmas(_refl(x, e, rho, sr, sb), R, t, *caps) == (0.0, 0.0)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed", range(3))
def test_fit_adaptive_equals_the_kernel(mode, seed):
    """fit_adaptive with sigmas a third of the errors (the excess sigmas are estimated,
    over the leave-one-out fits): the same sigmas (none / los to 1e-12, the same grid
    point; ml to one grid step of ``_excess_sigma``, cap / 2^16: the kernel's pose,
    1e-5 sigma off the optimum, may move the bisection by one step) and pose
    (``EXACT_SIGMA`` none / los, ``OPTIMISER_SIGMA`` ml)."""
    x, e, rho, y, sr, sb, _, _ = _scene(seed, m=6 + seed, noise=3.0)
    args = (_settings(mode), 0.5 / 300.0)
    got = reference.fit_adaptive(_refl(x, e, rho, sr, sb), *args)
    want = kernel.fit_adaptive(_refl(x, e, rho, sr, sb), *args)
    assert (got.sr > sr).any() or (got.sb > sb).any()
    step = 0.0 if mode != "ml" else 1.0 / 2**16
    extra = np.sqrt(got.sr**2 - sr**2), np.sqrt(got.sb**2 - sb**2)
    extra_k = np.sqrt(want.sr**2 - sr**2), np.sqrt(want.sb**2 - sb**2)
    np.testing.assert_allclose(extra[0], extra_k[0], rtol=1e-9, atol=1.01 * step * 25.0)
    np.testing.assert_allclose(extra[1], extra_k[1], rtol=1e-9, atol=1.01 * step * 0.5 / 300)
    tol = OPTIMISER_SIGMA if mode == "ml" else EXACT_SIGMA
    assert _sigmas(got.R, got.t, want.R, want.t, want.covariance) < tol


def _with_outlier(seed, m=8, outlier_mm=60.0, range_mm=5000.0):
    """``_scene`` with reflector ``seed % m`` 60 mm too far (a reflection behind it)."""
    x, e, rho, y, sr, sb, R, t = _scene(seed, m=m, range_mm=range_mm, sr_mm=2.0)
    bad = seed % m
    rho = rho.copy()
    rho[bad] += outlier_mm
    return x, e, rho, e * rho[:, None], sr, sb, R, t, bad


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed", range(3))
def test_worst_outlier_and_fit_with_outliers_drop_the_planted_outlier(mode, seed):
    """A reflector 60 mm off in range: worst_outlier names it, as the kernel does, and
    fit_with_outliers (no offset prior) keeps the same reflectors as the kernel with the
    same pose (``EXACT_SIGMA`` none / los, ``OPTIMISER_SIGMA`` ml), sigmas (1e-9) and chi^2;
    the pose is the truth's within 5 sigma."""
    x, e, rho, y, sr, sb, R, t, bad = _with_outlier(seed)
    fit = _settings(mode)
    refl = _refl(x, e, rho, sr, sb)
    norms = reference.fit_pose(refl, fit).norms
    assert reference.worst_outlier(refl, norms, fit) == bad
    assert kernel.worst_outlier(refl, norms, fit) == bad
    got = reference.fit_with_outliers(refl, fit, 0.5 / 300.0, NO_OFFSET)
    want = kernel.fit_with_outliers(refl, fit, 0.5 / 300.0, NO_OFFSET)
    expected = np.arange(len(x)) != bad
    np.testing.assert_array_equal(got.kept, expected)
    np.testing.assert_array_equal(want.kept, expected)
    tol = OPTIMISER_SIGMA if mode == "ml" else EXACT_SIGMA
    g, w = got.fit, want.fit
    assert _sigmas(g.R, g.t, w.R, w.t, w.covariance) < tol
    np.testing.assert_allclose(g.sr, w.sr, rtol=1e-9)
    np.testing.assert_allclose(g.sb, w.sb, rtol=1e-9)
    assert g.chi2 == pytest.approx(w.chi2, rel=1e-5 if mode == "ml" else 1e-9)
    assert got[2:] == (0.0, 0.0) and want[2:] == (0.0, 0.0)
    assert _sigmas(g.R, g.t, R, t, g.covariance) < 5.0


def test_worst_outlier_is_none_for_a_consistent_fit_and_the_largest_norm_below_five():
    x, e, rho, y, sr, sb, _, _ = _scene(3, m=8)
    fit = _settings("ml")
    norms = reference.fit_pose(_refl(x, e, rho, sr, sb), fit).norms
    assert reference.worst_outlier(_refl(x, e, rho, sr, sb), norms, fit) == -1
    four = _refl(x[:4], e[:4], rho[:4], sr[:4], sb[:4])
    norms = np.array([1.0, 7.0, 2.0, 6.5])
    assert reference.worst_outlier(four, norms, fit) == 1
    assert reference.worst_outlier(four, norms / 2, fit) == -1


#: ranges near enough for the image scale to fix the distance (the offset is observable)
NEAR_MM = 1500.0


@pytest.mark.parametrize("seed", range(4))
def test_common_range_offset_equals_the_kernel_and_recovers_a_planted_offset(seed):
    """30 mm added to every range at 1.5 m: common_range_offset recovers it within its
    sigma, as the kernel does. Tolerance to the kernel: 1e-4 posterior sigma (b; measured
    3e-6) and 1e-6 (its sigma). (The kernel's Jacobian once left out how the lateral
    sigmas (rho - b) sb move with b, which put its fixed point 1-5 % of sigma off the
    posterior mode; this test, at 0.1 sigma then, is what found it.)"""
    x, e, rho, _, sr, sb, R, t = _scene(seed, range_mm=NEAR_MM, sb_rad=5e-5, sr_mm=3.0)
    rho = rho + 30.0
    prior = RangeOffsetPrior(50.0, 0.0005, 0.01 / 300.0)
    refl = _refl(x, e, rho, sr, sb)
    first = kernel.fit_pose(refl, _settings("ml"))
    R0, t0 = first.R, first.t
    b, sigma = reference.common_range_offset(refl, R0, t0, prior)
    b_k, sigma_k = kernel.common_range_offset(refl, R0, t0, prior)
    assert abs(b - 30.0) < sigma < 10.0
    assert abs(b - b_k) < 1e-4 * sigma
    assert sigma == pytest.approx(sigma_k, rel=1e-6)
    # not estimated without a prior; the image scale alone when it is exact
    assert reference.common_range_offset(refl, R0, t0, NO_OFFSET) == (0.0, 0.0)
    exact_scale = RangeOffsetPrior(50.0, 0.0, 0.0)
    b0, s0 = reference.common_range_offset(refl, R0, t0, exact_scale)
    b0_k, s0_k = kernel.common_range_offset(refl, R0, t0, exact_scale)
    assert abs(b0 - b0_k) < 0.1 * s0 and s0 == pytest.approx(s0_k, rel=1e-3) and s0 < sigma


#: the common range offset planted with an outlier
OFFSET_MM = 5.0


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("seed", range(2))
def test_fit_with_outliers_with_an_offset_prior_equals_the_kernel(mode, seed):
    """Offset prior on, a planted 60 mm outlier and ``OFFSET_MM`` on every range at 1.5 m
    (a larger offset raises the excess range sigma before the offset is estimated, and
    the outlier then hides in it -- in the kernel as here): the same
    kept reflectors; the offset (only in the ml mode) within 0.1 of its sigma of the
    kernel's (``test_common_range_offset...``), and the final fit equal to the
    reference's fit_adaptive at the kernel's offset (``EXACT_SIGMA`` / ``OPTIMISER_SIGMA``):
    the offset step and the refit are each as tight as their arithmetic allows."""
    x, e, rho, _, sr, sb, R, t, bad = _with_outlier(seed, range_mm=NEAR_MM)
    rho = rho + OFFSET_MM
    prior = RangeOffsetPrior(50.0, 0.0005, 0.01 / 300.0)
    fit = _settings(mode)
    got = reference.fit_with_outliers(_refl(x, e, rho, sr, sb), fit, 0.5 / 300.0, prior)
    want = kernel.fit_with_outliers(_refl(x, e, rho, sr, sb), fit, 0.5 / 300.0, prior)
    np.testing.assert_array_equal(got.kept, want.kept)
    if mode != "los":  # the line of sight's excess range sigma may hide it (the kernel's too)
        np.testing.assert_array_equal(got.kept, np.arange(len(x)) != bad)
    g, w = got.fit, want.fit
    if mode != "ml":
        assert got[2:] == want[2:] == (0.0, 50.0)
        assert _sigmas(g.R, g.t, w.R, w.t, w.covariance) < EXACT_SIGMA
        return
    offset, sigma = got.offset_mm, got.offset_sigma_mm
    assert abs(offset - want.offset_mm) < 0.1 * sigma and abs(offset - OFFSET_MM) < 3 * sigma
    k = want.kept
    refit = reference.fit_adaptive(
        _refl(x[k], e[k], rho[k] - want.offset_mm, sr[k], sb[k]), fit, 0.5 / 300.0
    )
    assert _sigmas(refit.R, refit.t, w.R, w.t, w.covariance) < OPTIMISER_SIGMA
    np.testing.assert_allclose(refit.sr, w.sr, rtol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_bias_covariances_equal_the_kernels(seed):
    """range_bias_covariance and class_scale_covariance (three size classes, one of them
    empty): to 1e-6 (the reference's Jacobian is by central differences)."""
    x, e, rho, _, sr, sb, R, t = _scene(seed, m=5 + seed)
    refl = _refl(x, e, rho, sr, sb)
    got = reference.range_bias_covariance(refl, R, t, 15.0)
    want = kernel.range_bias_covariance(refl, R, t, 15.0)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())
    group = np.arange(len(x)) % 3
    group[group == 1] = 3  # class 1 has no reflector
    got = reference.class_scale_covariance(refl, R, t, group, 4, 1e-4, 0.002)
    want = kernel.class_scale_covariance(refl, R, t, group, 4, 1e-4, 0.002)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())


def test_a_range_bias_moves_the_pose_along_the_line_of_sight_by_itself():
    """Truth: adding b to every range moves the fitted pose by s b to first order, the
    response range_bias_covariance is built from (its square root, times b)."""
    x, e, rho, y, sr, sb, R, t = _scene(5, noise=0.0)
    b = 1.0
    shifted = reference.fit_pose(_refl(x, e, rho + b, sr, sb), _settings("ml"))
    moved = np.concatenate((Rotation.from_matrix(shifted.R @ R.T).as_rotvec(), shifted.t - t))
    cov = reference.range_bias_covariance(_refl(x, e, rho, sr, sb), R, t, b)
    np.testing.assert_allclose(np.outer(moved, moved), cov, atol=1e-4 * np.abs(cov).max())


def test_worst_outlier_keeps_the_lone_marker_that_alone_fixes_the_pose():
    """Four markers in a cluster and one alone 250 mm away (at 8 m, as glints leave a
    target): the fit without the lone one predicts it badly because it alone fixes the
    pose's tilt, not because it is wrong. worst_outlier (both implementations) drops the
    cluster's marker whose bearing is 12 sigma off, not the lone one: the residual is
    counted in sigmas of the prediction (``deleted_residual_norm``), and the lone
    marker's own residual in its measurement sigmas alone is the largest."""
    x = np.array(
        [
            [0.0, 0.0, 0.0],
            [40.0, 0.0, 0.0],
            [0.0, 40.0, 0.0],
            [40.0, 40.0, 5.0],
            [250.0, 180.0, 0.0],
        ]
    )
    R = Rotation.from_rotvec([0.2, -0.3, 0.1]).as_matrix()
    t = np.array([100.0, -50.0, 8000.0])
    p = x @ R.T + t
    rho = np.linalg.norm(p, axis=1)
    e = p / rho[:, None]
    sr = np.full(5, 3.0)
    sb = np.full(5, 1.5e-4)
    rng = np.random.default_rng(2)
    e = e + 0.5 * sb[:, None] * rng.normal(0, 1, e.shape)
    bad = 1
    side = np.cross(e[bad], [0.0, 0.0, 1.0])
    e[bad] += 12.0 * sb[bad] * side / np.linalg.norm(side)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    refl = _refl(x, e, rho, sr, sb)
    fit = _settings("ml", adapt=False)
    norms = reference.fit_pose(refl, fit).norms
    raw = []
    for j in range(5):
        _, Rj, tj = reference.fit_without(j, refl, fit)
        raw.append(
            np.linalg.norm(reference.whitened_residuals(reference.rows_of(refl, [j]), Rj, tj))
        )
    assert int(np.argmax(raw)) == 4  # the old rule's choice: the lone, correct marker
    assert reference.worst_outlier(refl, norms, fit) == bad
    assert kernel.worst_outlier(refl, norms, fit) == bad
    for j in range(5):
        assert reference.deleted_residual_norm(j, refl, fit) == pytest.approx(
            kernel.deleted_residual_norm(j, refl, fit), rel=0.02
        )  # numerical Jacobian; fits to the optimiser's tolerance
