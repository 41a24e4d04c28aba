"""Covariance calibration: the factor per range recovered from NEES values, its
interpolation and stored form, its effect on a pipeline's result, and on the simulator a
calibrated covariance consistent on frames it was not fitted on."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.calibration.covariance import (
    CovarianceScale,
    auto_knots,
    fit_covariance_scale,
    pose_nees,
)
from tofpose.core.geometry import RigidTransform
from tofpose.sim.bench import R_FACING


def test_pose_nees_of_errors_drawn_from_the_covariance_is_chi_square_6():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6))
    cov = A @ A.T * 1e-4 + np.eye(6) * 1e-6
    L = np.linalg.cholesky(cov)
    R_ref, t_ref = R_FACING, np.array([10.0, -20.0, 3000.0])
    values = []
    for _ in range(4000):
        e = L @ rng.normal(size=6)
        R = Rotation.from_rotvec(e[:3]).as_matrix() @ R_ref
        values.append(pose_nees(R, t_ref + e[3:], cov, R_ref, t_ref))
    assert np.mean(values) == pytest.approx(6.0, rel=0.05)
    assert np.mean(np.array(values) <= 12.59) == pytest.approx(0.95, abs=0.015)


def test_the_fit_recovers_the_factor_per_range_and_leaves_out_failed_poses():
    rng = np.random.default_rng(1)
    true = {700.0: 0.2, 2000.0: 0.5, 6000.0: 1.6}
    ranges, nees = [], []
    for r, f in true.items():
        n = 400
        ranges += list(r * np.exp(rng.uniform(-0.15, 0.15, n)))  # spread around the knot
        nees += list(f * rng.chisquare(6, n))
    nees[3] = 5000.0  # a failed pose in the first group: left out, counted
    fit = fit_covariance_scale(ranges, nees, list(true))
    assert fit.frames == (400, 400, 400) and fit.outliers == (1, 0, 0)
    for got, want in zip(fit.scale.factors, true.values(), strict=True):
        assert got == pytest.approx(want, rel=0.08)  # 400 chi-square draws: ~3.5 % sigma


def test_knots_with_too_few_frames_are_named():
    with pytest.raises(ValueError, match=r"too few at 8000 mm \(3\)"):
        fit_covariance_scale([1000.0] * 30 + [8000.0] * 3, [6.0] * 33, [1000.0, 8000.0])


def test_auto_knots_cover_the_span_with_enough_frames_each():
    rng = np.random.default_rng(2)
    ranges = np.exp(rng.uniform(np.log(700.0), np.log(8000.0), 300))
    knots = auto_knots(ranges)
    assert knots[0] == pytest.approx(ranges.min()) and knots[-1] == pytest.approx(ranges.max())
    assert np.all(np.diff(np.log(knots)) <= np.log(1.5) + 1e-9)
    fit_covariance_scale(ranges, np.full(300, 6.0), knots)  # every knot has >= 20 frames
    assert len(auto_knots(ranges[:30])) == 1  # 30 frames: one knot


def test_the_factor_interpolates_in_log_range_and_holds_at_the_ends():
    s = CovarianceScale((1000.0, 4000.0), (0.2, 1.0))
    assert s.factor_at(500.0) == 0.2 and s.factor_at(9000.0) == 1.0
    assert s.factor_at(2000.0) == pytest.approx(0.6)  # halfway in log range
    assert CovarianceScale.from_dict(s.to_dict()) == s


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"ranges_mm": [1000.0]}, "lacks 'factors'"),
        ({"ranges_mm": [1000.0, 900.0], "factors": [1.0, 1.0]}, "positive and increasing"),
        ({"ranges_mm": [1000.0], "factors": [0.0]}, "factors must be positive"),
        ({"ranges_mm": [1000.0, 2000.0], "factors": [1.0]}, "2 ranges and 1 factors"),
        ({"ranges_mm": 1000.0, "factors": [1.0]}, "must be lists"),
    ],
)
def test_a_bad_stored_scale_is_refused_with_what_is_wrong(doc, message):
    with pytest.raises(ValueError, match=message):
        CovarianceScale.from_dict(doc)


def test_the_pipeline_scales_only_the_reported_covariance():
    cam, cat = CameraModel(), paper_target()
    scale = CovarianceScale((1000.0, 5000.0), (0.25, 0.5))
    T = RigidTransform(R_FACING, np.array([20.0, -10.0, 2500.0]))
    f = render(T, seed=3)
    a = PosePipeline(cam, cat).process(f.gray, f.distance_mm)
    b = PosePipeline(cam, cat, covariance_scale=scale).process(f.gray, f.distance_mm)
    assert a.ok and b.ok
    np.testing.assert_array_equal(a.t_mm, b.t_mm)
    np.testing.assert_array_equal(a.R, b.R)
    factor = scale.factor_at(float(np.linalg.norm(a.t_mm)))
    assert 0.25 < factor < 0.5
    np.testing.assert_allclose(b.covariance, a.covariance * factor, rtol=1e-12)


def _nees_of_frames(pipe, z_mm, n, seed):
    """NEES of n frames of random attitudes (<= 10 deg) at about z_mm."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        rot = Rotation.from_rotvec(rng.normal(size=3) * np.radians(4.0)).as_matrix()
        T = RigidTransform(rot @ R_FACING, np.array([*rng.uniform(-150, 150, 2), z_mm]))
        f = render(T, seed=seed * 1000 + k)
        pipe.reset()
        r = pipe.process(f.gray, f.distance_mm)
        if r.ok:
            out.append(
                (float(np.linalg.norm(T.t_mm)), pose_nees(r.R, r.t_mm, r.covariance, T.R, T.t_mm))
            )
    return np.array(out)


def test_a_calibrated_covariance_is_consistent_on_frames_it_was_not_fitted_on():
    """The model's covariance is conservative at 1.5 m (floors); calibrated on 40 frames,
    the mean NEES of 40 other frames lies in its 95 % band."""
    from scipy.stats import chi2

    cam, cat = CameraModel(), paper_target()
    config = PipelineConfig(range_bias_sigma_mm=0.0)  # the simulator has no range bias
    cal = _nees_of_frames(PosePipeline(cam, cat, config), 1500.0, 40, seed=1)
    fit = fit_covariance_scale(cal[:, 0], cal[:, 1], [1500.0])
    test = _nees_of_frames(PosePipeline(cam, cat, config), 1500.0, 40, seed=2)
    lo, hi = chi2.ppf([0.025, 0.975], 6 * len(test)) / len(test)
    assert np.mean(test[:, 1]) < lo  # the model's covariance: too wide
    calibrated = test[:, 1] / fit.scale.factor_at(1500.0)
    assert lo <= np.mean(calibrated) <= hi, (np.mean(calibrated), lo, hi)
