import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.core.catalog import paper_target
from tofpose.core.geometry import rotation_angle_deg
from tofpose.stages.pose.pose import (
    refine_line_of_sight,
    refine_maximum_likelihood,
    reflector_whitened_norms,
    systematic_sigmas,
    weighted_absolute_orientation,
)
from tofpose.stages.pose.records import RangeOffsetPrior, Reflectors
from tofpose.stages.pose.reference import pose as reference


def _truth(seed=0):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    t = np.array([30.0, -40.0, 3000.0])
    return R, t


def test_weighted_svd_exact_on_noiseless_data():
    x = paper_target().positions_mm
    R, t = _truth()
    y = x @ R.T + t
    R_est, t_est = weighted_absolute_orientation(x, y, np.linspace(1, 3, len(x)))
    np.testing.assert_allclose(R_est, R, atol=1e-10)
    np.testing.assert_allclose(t_est, t, atol=1e-7)


def test_weighted_svd_agrees_with_scipy_align_vectors():
    rng = np.random.default_rng(3)
    x = paper_target().positions_mm
    R, t = _truth(3)
    y = x @ R.T + t + rng.normal(0, 2.0, x.shape)
    w = rng.uniform(0.5, 2.0, len(x))
    R_est, t_est = weighted_absolute_orientation(x, y, w)
    xc = x - (w @ x) / w.sum()
    yc = y - (w @ y) / w.sum()
    rot, _ = Rotation.align_vectors(yc, xc, weights=w)
    assert rotation_angle_deg(R_est, rot.as_matrix()) < 1e-6
    np.testing.assert_allclose(t_est, (w @ y) / w.sum() - R_est @ ((w @ x) / w.sum()), atol=1e-9)


def test_reflection_fix_returns_a_proper_rotation():
    x = paper_target().positions_mm
    y = x * np.array([-1.0, 1.0, 1.0])  # a mirror image: best orthogonal fit is a reflection
    R, _ = weighted_absolute_orientation(x, y)
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("x", "msg"), [(np.zeros((2, 3)), "at least 3"), (np.zeros((4, 2)), "\\(m, 3\\)")]
)
def test_weighted_svd_errors(x, msg):
    with pytest.raises(ValueError, match=msg):
        weighted_absolute_orientation(x, x)


def test_line_of_sight_refinement_recovers_truth_from_bad_ranges():
    x = paper_target().positions_mm
    R, t = _truth(5)
    y = x @ R.T + t
    e = y / np.linalg.norm(y, axis=1, keepdims=True)
    rng = np.random.default_rng(5)
    y_meas = e * (np.linalg.norm(y, axis=1) + rng.normal(0, 30, len(y)))[:, None]
    R0, t0 = weighted_absolute_orientation(x, y_meas)
    out = refine_line_of_sight(x, e, R0, t0, tol=1e-9, max_iterations=5000)
    assert rotation_angle_deg(out.R, R) < 1e-3
    np.testing.assert_allclose(out.t, t, atol=0.05)
    # The Eq. 52 residual falls monotonically towards zero on exact bearings.
    assert out.residuals[-1] < 0.01 * out.residuals[0]


def test_maximum_likelihood_covariance_predicts_the_spread():
    x = paper_target().positions_mm
    R, t = _truth(7)
    y = x @ R.T + t
    rho_true = np.linalg.norm(y, axis=1)
    e_true = y / rho_true[:, None]
    sig_r, sig_b = np.full(8, 5.0), np.full(8, 3e-4)
    rng = np.random.default_rng(11)
    errs, cov = [], None
    for _ in range(300):
        e = e_true + rng.normal(0, 3e-4, e_true.shape)
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        rho = rho_true + rng.normal(0, 5.0, 8)
        R0, t0 = weighted_absolute_orientation(x, e * rho[:, None])
        ml = refine_maximum_likelihood(x, e, rho, R0, t0, sig_r, sig_b)
        errs.append(np.concatenate((Rotation.from_matrix(ml.R @ R.T).as_rotvec(), ml.t - t)))
        cov = ml.covariance
    emp = np.std(errs, axis=0)
    pred = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(emp / pred, 1.0, atol=0.2)


def test_whitened_norm_counts_sigmas_off_the_fit():
    """A reflector 5 mm too far along its line of sight (range sigma 1 mm) sits 5 sigmas
    off; one 3 mm sideways at 3 m with a 1e-3 rad bearing sigma sits 1 sigma off."""
    x = paper_target().positions_mm
    R, t = _truth()
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e = y / rho[:, None]
    rho[0] += 5.0
    side = np.cross(e[1], [0.0, 0.0, 1.0])
    y1 = y[1] + 3.0 * side / np.linalg.norm(side)
    e[1], rho[1] = y1 / np.linalg.norm(y1), np.linalg.norm(y1)
    z = reflector_whitened_norms(x, e, rho, R, t, np.ones(len(x)), np.full(len(x), 1e-3))
    assert z[0] == pytest.approx(5.0, rel=1e-6)
    assert z[1] == pytest.approx(3.0 / rho[1] / 1e-3, rel=1e-3)
    assert np.all(z[2:] < 1e-6)


def _noisy_observations(seed: int, bearing_sigma_rad: float, range_sigma_mm: float):
    """The paper target at 3 m seen with bearing and range errors of known sigmas, and
    the fit of those observations with a model that knows neither (tiny sigmas)."""
    x = paper_target().positions_mm
    R, t = _truth(seed)
    y = x @ R.T + t
    rho_true = np.linalg.norm(y, axis=1)
    e_true = y / rho_true[:, None]
    rng = np.random.default_rng(seed)
    e = e_true + rng.normal(0, bearing_sigma_rad, e_true.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rho = rho_true + rng.normal(0, range_sigma_mm, len(x))
    sr, sb = np.full(len(x), 0.5), np.full(len(x), 1e-5)
    R0, t0 = weighted_absolute_orientation(x, e * rho[:, None])
    ml = refine_maximum_likelihood(x, e, rho, R0, t0, sr, sb)
    return x, e, rho, ml.R, ml.t, sr, sb


@pytest.mark.parametrize(("bearing_sigma_rad", "range_sigma_mm"), [(3e-4, 0.0), (0.0, 8.0)])
def test_excess_sigmas_go_to_the_kind_of_measurement_that_has_them(
    bearing_sigma_rad, range_sigma_mm
):
    """Bearing errors raise the bearing component, and the reverse; each is of the size
    the errors were made with (medians of 8 reflectors, over 40 draws). The fit with the
    model's tiny bearing sigmas tilts to follow the bearings and leaves a few mm on the
    ranges: the range component takes that (~2 mm), where one range sigma for all
    residuals had to reach its 200 mm cap (lateral errors of ~1 mm at 3 m over a 0.03 mm
    model)."""
    estimates = np.array(
        [
            systematic_sigmas(
                *_noisy_observations(s, bearing_sigma_rad, range_sigma_mm),
                max_range_mm=200.0,
                max_bearing_rad=0.1,
            )
            for s in range(40)
        ]
    )
    er, eb = np.median(estimates, axis=0)
    if bearing_sigma_rad > 0:
        assert er < 5.0  # mm, of a 200 mm cap
        assert eb == pytest.approx(bearing_sigma_rad, rel=0.35)
    else:
        assert eb < 2e-5  # rad: the bearings are exact
        assert er == pytest.approx(range_sigma_mm, rel=0.35)


def test_excess_sigmas_stop_at_what_the_sensor_can_do():
    x, e, rho, R, t, sr, sb = _noisy_observations(3, 3e-3, 60.0)
    er, eb = systematic_sigmas(x, e, rho, R, t, sr, sb, max_range_mm=25.0, max_bearing_rad=5e-4)
    assert (er, eb) == (25.0, 5e-4)
    assert systematic_sigmas(x, e, rho, R, t, sr, sb, 25.0, 5e-4) == (er, eb)


@pytest.mark.parametrize(("bearing_sigma_rad", "expect_found"), [(2e-5, True), (2e-3, False)])
def test_a_common_range_offset_is_found_when_the_image_scale_fixes_the_distance(
    bearing_sigma_rad, expect_found
):
    """Ranges all read 20 mm long (an uncalibrated camera's offset). With sharp bearings
    the target's image scale fixes its distance and the offset is estimated (posterior
    sigma well below the 8 mm prior); with blurred ones the data hardly know it: it is
    shrunk towards the prior's 0, with most of the prior's sigma."""
    from tofpose.stages.pose.kernels.pose import common_range_offset

    x = paper_target().positions_mm
    R, t = _truth(5)
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e = y / rho[:, None]
    rng = np.random.default_rng(2)
    e = e + rng.normal(0, bearing_sigma_rad, e.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rho_measured = rho + 20.0 + rng.normal(0, 1.0, len(x))
    sr, sb = np.full(len(x), 1.0), np.full(len(x), bearing_sigma_rad)
    R0, t0 = weighted_absolute_orientation(x, e * rho_measured[:, None])
    ml = refine_maximum_likelihood(x, e, rho_measured, R0, t0, sr, sb)
    exact_scale = RangeOffsetPrior(sigma_mm=8.0, focal_length_sigma_rel=0.0, centroid_bias_rad=0.0)
    refl = Reflectors(x=x, e=e, rho=rho_measured, sr=sr, sb=sb)
    offset, sigma = common_range_offset(refl, ml.R, ml.t, exact_scale)
    if expect_found:
        assert offset == pytest.approx(20.0, abs=3 * sigma) and sigma < 2.0
    else:
        assert sigma > 5.0  # most of the 8 mm prior: the data hardly know it
        assert abs(offset) < 20.0 - sigma  # shrunk towards the prior's 0


def _scaled_about_mean(e, scale):
    """Bearings e (m, 3) whose offsets from their mean bearing are ``scale`` times
    larger (a focal-length error), unit length."""
    mean = e.mean(axis=0)
    mean /= np.linalg.norm(mean)
    along = e @ mean
    out = mean[None, :] * along[:, None] + scale * (e - mean[None, :] * along[:, None])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def test_an_image_scale_error_is_not_read_as_a_range_offset():
    """Exact ranges, sharp bearings whose image is 0.5 % too large (a focal length 0.5 %
    off, or a centroid error common to small markers). Assuming the scale exact, the fit
    reads the scale error as a range offset of ~0.5 % of the range, tens of its own
    sigmas (the confidently wrong pose it would feed); with the scale's uncertainty as a
    parameter (``pattern_scale_sigma``) the offset stays within 3 of its sigmas of the
    true 0, and the sigma says the image cannot fix it to better than ~the scale's."""
    from tofpose.stages.pose.kernels.pose import common_range_offset

    x = paper_target().positions_mm
    R, t = _truth(5)
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    rng = np.random.default_rng(3)
    e = _scaled_about_mean(y / rho[:, None], 1.005) + rng.normal(0, 2e-5, y.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    rho_measured = rho + rng.normal(0, 1.0, len(x))
    sr, sb = np.full(len(x), 1.0), np.full(len(x), 2e-5)
    R0, t0 = weighted_absolute_orientation(x, e * rho_measured[:, None])
    ml = refine_maximum_likelihood(x, e, rho_measured, R0, t0, sr, sb)
    refl = Reflectors(x=x, e=e, rho=rho_measured, sr=sr, sb=sb)
    naive, naive_sigma = common_range_offset(refl, ml.R, ml.t, RangeOffsetPrior(8.0, 0.0, 0.0))
    assert abs(naive) > 10 * naive_sigma and abs(naive) > 5.0
    offset, sigma = common_range_offset(refl, ml.R, ml.t, RangeOffsetPrior(8.0, 0.005, 0.0))
    assert abs(offset) < 3 * sigma
    assert sigma > 0.3 * 0.005 * np.linalg.norm(t)


def test_the_image_scale_prior_adds_the_centroid_bias_over_the_pattern_radius():
    """sigma_kappa^2 = sigma_f^2 + (c / r_rms)^2, r_rms the rms angle of the bearings
    from their mean (here four bearings 0.01 rad off axis: r_rms = 0.01)."""
    from tofpose.stages.pose.kernels.pose import pattern_scale_sigma

    a = 0.01
    e = np.array(
        [
            [np.sin(a), 0, np.cos(a)],
            [-np.sin(a), 0, np.cos(a)],
            [0, np.sin(a), np.cos(a)],
            [0, -np.sin(a), np.cos(a)],
        ]
    )
    sigma, mean = pattern_scale_sigma(e, RangeOffsetPrior(8.0, 0.002, 1e-4))
    assert mean == pytest.approx([0, 0, 1])
    assert sigma == pytest.approx(np.hypot(0.002, 1e-4 / np.sin(a)), rel=1e-9)


def test_per_size_scale_errors_give_the_covariance_the_pose_errors_have():
    """Monte Carlo: the bearings of each marker size scaled about the pattern's mean
    bearing by its own kappa ~ N(0, (c / r_size)^2) (a centroid error common to the
    markers of one size) plus one common to all ~ N(0, 0.2 %^2) (the focal length),
    fitted by ML; the pose errors' mean NEES against the fit's
    covariance plus ``class_scale_covariance`` is 6 (within its Monte-Carlo spread),
    and without that term it is several times too large: the fit alone does not know."""
    from tofpose.stages.pose.kernels.pose import class_scale_covariance

    cat = paper_target()
    x = cat.positions_mm
    _, size = np.unique(cat.diameters_mm, return_inverse=True)
    R = Rotation.from_euler("xyz", [5, -8, 3], degrees=True).as_matrix()
    t = np.array([-140.0, -100.0, 3100.0])
    y = x @ R.T + t
    rho = np.linalg.norm(y, axis=1)
    e0 = y / rho[:, None]
    mean = e0.mean(axis=0) / np.linalg.norm(e0.mean(axis=0))
    along = e0 @ mean
    radial = e0 - mean * along[:, None]
    r_size = [np.sqrt(np.mean(1 - along[size == k] ** 2)) for k in range(2)]
    bias_rad, focal_rel, sb_rad, sr_mm = 3e-4, 2e-3, 2e-5, 1.0
    sr, sb = np.full(len(x), sr_mm), np.full(len(x), sb_rad)
    rng = np.random.default_rng(7)
    d2 = {"with": [], "without": []}
    for _ in range(300):
        kappa = rng.normal(0, bias_rad / np.array(r_size))[size] + rng.normal(0, focal_rel)
        e = mean * along[:, None] + (1 + kappa[:, None]) * radial
        e = e + rng.normal(0, sb_rad, e.shape)
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        rho_m = rho + rng.normal(0, sr_mm, len(x))
        ml = refine_maximum_likelihood(x, e, rho_m, R, t, sr, sb)
        err = np.concatenate([Rotation.from_matrix(ml.R @ R.T).as_rotvec(), ml.t - t])
        refl = Reflectors(x=x, e=e, rho=rho_m, sr=sr, sb=sb)
        extra = class_scale_covariance(refl, ml.R, ml.t, size, 2, bias_rad, focal_rel)
        d2["with"].append(err @ np.linalg.solve(ml.covariance + extra, err))
        d2["without"].append(err @ np.linalg.solve(ml.covariance, err))
    assert np.mean(d2["with"]) == pytest.approx(6.0, rel=0.2)
    assert np.mean(d2["without"]) > 3 * 6.0


def _far_observations(rng, ids, R, t, sb_rad, sr_mm):
    """The paper target's reflectors ``ids`` (0-based) seen at (R, t) with Gaussian
    bearing and range errors of the given sigmas: x, e, rho."""
    x = paper_target().positions_mm[ids]
    y = x @ R.T + t
    rho_true = np.linalg.norm(y, axis=1)
    e = y / rho_true[:, None] + rng.normal(0, sb_rad, y.shape)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    return x, e, rho_true + rng.normal(0, sr_mm, len(ids))


def _error(R, t, R_true, t_true):
    return np.concatenate([Rotation.from_matrix(R @ R_true.T).as_rotvec(), t - t_true])


def test_leave_one_out_covariance_is_the_spread_of_the_refits_about_the_pose():
    """Against the exact jackknife: each reflector left out in turn, the others refitted
    by ML to convergence from the pose, the rotation difference as scipy's rotation
    vector. The one Gauss-Newton step per reflector (exact to second order) gives each
    variance within 20 % of the converged refits' (6-13 % larger in this draw at 6 m:
    the step overshoots slightly, on the safe side)."""
    from tofpose.stages.pose.pose import leave_one_out_covariance

    rng = np.random.default_rng(3)
    R = Rotation.from_euler("xyz", [12, -7, 30], degrees=True).as_matrix()
    t = np.array([300.0, -200.0, 6000.0])
    ids = np.arange(8)
    sr, sb = np.full(8, 8.0), np.full(8, 2e-4)
    x, e, rho = _far_observations(rng, ids, R, t, 2e-4, 8.0)
    ml = refine_maximum_likelihood(x, e, rho, R, t, sr, sb)
    got = leave_one_out_covariance(x, e, rho, ml.R, ml.t, sr, sb)
    want = np.zeros((6, 6))
    for j in range(8):
        k = ids != j
        f = refine_maximum_likelihood(x[k], e[k], rho[k], ml.R, ml.t, sr[k], sb[k])
        d = _error(f.R, f.t, ml.R, ml.t)
        want += np.outer(d, d)
    want *= 7 / 8
    # the statement (one step each, by tofpose.reference) to rounding
    stated = reference.leave_one_out_spread(Reflectors(x, e, rho, sr, sb), ml.R, ml.t)
    np.testing.assert_allclose(got, stated, rtol=1e-5, atol=1e-6 * np.abs(stated).max())
    ratio = np.diag(got) / np.diag(want)
    assert np.all((ratio > 0.9) & (ratio < 1.2)), ratio
    np.testing.assert_allclose(got, want, rtol=0.4, atol=0.05 * np.abs(want).max())
    assert np.any(want != 0)
    assert leave_one_out_covariance(x[:3], e[:3], rho[:3], ml.R, ml.t, sr[:3], sb[:3]) is None


def test_covariance_envelope_contains_both_and_is_the_model_when_it_is_wider():
    from tofpose.stages.pose.pose import covariance_envelope

    rng = np.random.default_rng(1)
    for _ in range(20):
        A0, B0 = rng.normal(size=(6, 6)), rng.normal(size=(6, 6))
        A, B = A0 @ A0.T + 0.1 * np.eye(6), B0 @ B0.T
        env = covariance_envelope(A, B)
        np.testing.assert_allclose(env, reference.covariance_envelope(A, B), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(env, env.T)
        assert np.linalg.eigvalsh(env - A).min() > -1e-9 * np.abs(env).max()
        assert np.linalg.eigvalsh(env - B).min() > -1e-9 * np.abs(env).max()
        np.testing.assert_allclose(covariance_envelope(A, 0.5 * A), A, rtol=1e-9)
        np.testing.assert_allclose(covariance_envelope(A, 2.0 * A), 2.0 * A, rtol=1e-9)
    assert covariance_envelope(A, None) is A
    np.testing.assert_array_equal(covariance_envelope(A, np.full((6, 6), np.nan)), A)
    np.testing.assert_array_equal(covariance_envelope(-A, B), -A)  # not positive definite


def test_a_biased_marker_that_alone_fixes_the_tilt_is_caught_by_the_leave_one_out_spread():
    """Known truth at 8 m with five of the paper target's reflectors: the four small ones
    (close together in the image) and one large one, whose bearing alone sets the lever
    the attitude hangs on. Its bearing is off by 6 of its sigmas (a marker partly hidden
    by something in front of it): the ML fit goes through it (no residual reveals it)
    and the model's covariance calls the pose beyond 3 sigmas (chi^2_6 0.9973 = 20.06);
    the envelope with the leave-one-out spread mostly does not (five points are few: a
    jackknife of five is itself uncertain). With every marker unbiased, the envelope's
    mean NEES stays within a factor 0.6 of the model's."""
    from tofpose.stages.pose.pose import covariance_envelope, leave_one_out_covariance

    R = Rotation.from_euler("xyz", [15, -10, 20], degrees=True).as_matrix()
    t = np.array([400.0, -300.0, 8000.0])
    ids = np.array([0, 1, 2, 3, 4])
    sb_rad, sr_mm = 0.035 / 325.0, 15.0  # 0.035 px at fx 325; a small marker's range
    sr, sb = np.full(5, sr_mm), np.full(5, sb_rad)
    rng = np.random.default_rng(4)
    d2 = {"model": [], "envelope": []}
    clean = {"model": [], "envelope": []}
    for _ in range(200):
        x, e, rho = _far_observations(rng, ids, R, t, sb_rad, sr_mm)
        fits = {}
        for biased in (True, False):
            e_b = e.copy()
            if biased:
                side = np.cross(e_b[4], [0.0, 0.0, 1.0])
                e_b[4] += 6 * sb_rad * side / np.linalg.norm(side)
                e_b[4] /= np.linalg.norm(e_b[4])
            ml = refine_maximum_likelihood(x, e_b, rho, R, t, sr, sb)
            err = _error(ml.R, ml.t, R, t)
            env = covariance_envelope(
                ml.covariance, leave_one_out_covariance(x, e_b, rho, ml.R, ml.t, sr, sb)
            )
            fits[biased] = (
                err @ np.linalg.solve(ml.covariance, err),
                err @ np.linalg.solve(env, err),
            )
        d2["model"].append(fits[True][0])
        d2["envelope"].append(fits[True][1])
        clean["model"].append(fits[False][0])
        clean["envelope"].append(fits[False][1])
    beyond_model = np.mean(np.array(d2["model"]) > 20.06)
    beyond_envelope = np.mean(np.array(d2["envelope"]) > 20.06)
    assert beyond_model > 0.9  # the model is fooled nearly always (0.96 in this run)
    assert beyond_envelope < 0.2  # the envelope mostly not (0.125: five points are few)
    assert np.median(d2["envelope"]) < 0.25 * np.median(d2["model"])
    assert np.mean(clean["model"]) == pytest.approx(6.0, rel=0.25)
    # unbiased: the envelope widens the model's ellipsoid a little, not several-fold
    assert np.mean(clean["envelope"]) > 0.6 * np.mean(clean["model"])
