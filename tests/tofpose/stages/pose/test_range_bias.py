"""The range bias learned over a recording's frames: each frame's offset likelihood (its
posterior with the prior divided out) and the maximum-likelihood mean and spread of the
offsets, against offsets drawn with a known mean and spread."""

import numpy as np
import pytest

from tofpose.stages.pose.range_bias import MIN_FRAMES, learn_range_bias
from tofpose.stages.pose.records import NO_RANGE_OFFSET, RangeOffset

PRIOR_MM = 15.0


def _posterior(
    m_mm: float, v_mm2: float, prior_mm: float = PRIOR_MM, prior_mean_mm: float = 0.0
) -> RangeOffset:
    """The RangeOffset a fit reports whose frame alone says N(m, v) of the offset, under
    the prior N(prior_mean, prior^2): the product of the two Gaussians."""
    precision = 1.0 / v_mm2 + 1.0 / prior_mm**2
    mean = (m_mm / v_mm2 + prior_mean_mm / prior_mm**2) / precision
    return RangeOffset(mean, float(np.sqrt(1.0 / precision)), prior_mm, prior_mean_mm)


def _frames(rng, n: int, tau_mm: float, mean_mm: float = 0.0) -> list[RangeOffset]:
    """n frames whose true offsets spread by ``tau_mm`` about ``mean_mm``, each measured
    with its own noise (sigma 1-6 mm, as the image scale tells it at 2-8 m)."""
    sd = rng.uniform(1.0, 6.0, n)
    true = rng.normal(mean_mm, tau_mm, n) if tau_mm > 0 else np.full(n, mean_mm)
    return [_posterior(t + rng.normal(0.0, s), s**2) for t, s in zip(true, sd, strict=True)]


@pytest.mark.parametrize("prior_mean_mm", [0.0, -6.0])
def test_a_frames_likelihood_is_its_posterior_with_the_prior_divided_out(prior_mean_mm):
    m, v = _posterior(7.0, 4.0, prior_mean_mm=prior_mean_mm).likelihood()
    assert m == pytest.approx(7.0)
    assert v == pytest.approx(4.0)


def test_a_frame_that_tells_nothing_has_no_likelihood():
    assert RangeOffset(0.0, PRIOR_MM, PRIOR_MM).likelihood() is None  # posterior = prior
    assert NO_RANGE_OFFSET.likelihood() is None  # no offset modelled
    assert RangeOffset(0.0, 3.0, 0.0).likelihood() is None  # no prior to divide out


@pytest.mark.parametrize(("tau_mm", "mean_mm"), [(0.0, 0.0), (4.0, 0.0), (10.0, 0.0), (4.0, -8.0)])
def test_the_learned_mean_and_spread_are_the_drawn_ones(tau_mm, mean_mm):
    rng = np.random.default_rng([7, int(tau_mm), int(-mean_mm)])
    learned = learn_range_bias(_frames(rng, 400, tau_mm, mean_mm))
    assert learned is not None
    assert learned.n_frames == 400
    # the estimates' own standard errors decide how close: 3 of them
    assert abs(learned.tau_mm**2 - tau_mm**2) < 3 * learned.tau2_se_mm2 + 0.5
    assert abs(learned.mean_mm - mean_mm) < 3 * learned.mean_se_mm
    # the standard errors are the estimates' own: their spread over repeated draws


def test_the_standard_errors_are_the_spread_of_the_estimates_over_repeated_draws():
    """Over 200 recordings of 64 frames each, the mean's reported standard error is the
    spread of the learned means, and the spread's is that of the learned tau^2."""
    rng = np.random.default_rng(14)
    learned = [learn_range_bias(_frames(rng, 64, 4.0, 2.0)) for _ in range(200)]
    assert all(lb is not None for lb in learned)
    means = np.array([lb.mean_mm for lb in learned])
    tau2 = np.array([lb.tau_mm**2 for lb in learned])
    assert np.std(means) == pytest.approx(np.median([lb.mean_se_mm for lb in learned]), rel=0.2)
    assert np.std(tau2) == pytest.approx(np.median([lb.tau2_se_mm2 for lb in learned]), rel=0.3)


def test_poorly_told_offsets_do_not_widen_a_calibrated_prior():
    """Frames that each tell the offset to ~40 mm (far or small targets) leave a large
    standard error on the spread: the learned sigma then exceeds a range calibration's
    2 mm, and the prior stays at 2 mm; a spread shown beyond doubt does widen it."""
    poor = learn_range_bias(
        [_posterior(m, 40.0**2) for m in np.random.default_rng(15).normal(0.0, 40.0, 64)]
    )
    assert poor is not None and poor.sigma_mm > 2.0
    assert poor.prior_sigma_mm(2.0) == 2.0
    assert poor.prior_sigma_mm(15.0) <= 15.0
    wide = learn_range_bias(_frames(np.random.default_rng(16), 200, 20.0))
    assert wide is not None and wide.wider_than(15.0)
    assert wide.prior_sigma_mm(15.0) == wide.sigma_mm > 15.0


def test_nan_offsets_tell_nothing():
    rng = np.random.default_rng(17)
    nan = [RangeOffset(float("nan"), 3.0, PRIOR_MM)] * 20
    assert learn_range_bias(nan + _frames(rng, MIN_FRAMES - 1, 0.0)) is None
    learned = learn_range_bias(nan + _frames(rng, MIN_FRAMES, 0.0))
    assert learned is not None and learned.n_frames == MIN_FRAMES
    assert learned.n_outliers == 0  # they are not counted as left out
    assert np.isfinite(learned.sigma_mm) and np.isfinite(learned.mean_mm)


def test_the_summary_gives_the_sigmas_the_frames_are_measured_with():
    poor = learn_range_bias(
        [_posterior(m, 40.0**2) for m in np.random.default_rng(18).normal(0.0, 40.0, 64)]
    )
    assert poor is not None
    line = poor.summary(15.0, 2.0)
    used = poor.prior_sigma_mm(15.0)
    assert f"sigma {used:.1f} mm (2.0 mm inside a range correction's span)" in line


def test_a_calibrated_cameras_frames_shrink_the_prior_far_below_the_uncalibrated_one():
    learned = learn_range_bias(_frames(np.random.default_rng(8), 64, 0.0))
    assert learned is not None
    assert learned.sigma_mm < 0.25 * PRIOR_MM


def test_a_constant_offset_is_learned_and_the_prior_stays_narrow():
    """A camera whose offset is 9 mm on every frame: the mean reads it, the spread about
    it is ~0, so the prior is N(~9, a few mm): the offset is taken out, not covered."""
    learned = learn_range_bias(_frames(np.random.default_rng(9), 200, 0.0, mean_mm=9.0))
    assert learned is not None
    assert learned.mean_mm == pytest.approx(9.0, abs=3 * learned.mean_se_mm)
    assert learned.tau_mm < 1.5
    assert learned.sigma_mm < 0.25 * PRIOR_MM


def test_frames_measured_with_a_learned_prior_learn_the_same():
    """The likelihoods divide out whatever prior the frames were measured with: frames
    measured with N(9, 3^2) say what frames measured with N(0, 15^2) say."""
    rng = np.random.default_rng(12)
    sd = rng.uniform(1.0, 6.0, 100)
    m = 9.0 + rng.normal(0.0, 2.0, 100) + rng.normal(0.0, sd)
    a = learn_range_bias([_posterior(x, s**2) for x, s in zip(m, sd, strict=True)])
    b = learn_range_bias([_posterior(x, s**2, 3.0, 9.0) for x, s in zip(m, sd, strict=True)])
    assert a is not None and b is not None
    assert b.mean_mm == pytest.approx(a.mean_mm)
    assert b.tau_mm == pytest.approx(a.tau_mm)


def test_a_wrong_frames_offset_is_left_out():
    frames = _frames(np.random.default_rng(10), 40, 0.0)
    frames.append(_posterior(400.0, 4.0))  # a wrong pose's offset
    learned = learn_range_bias(frames)
    assert learned is not None
    assert learned.n_outliers == 1
    assert learned.n_frames == 40
    assert learned.sigma_mm < 0.25 * PRIOR_MM


def test_too_few_frames_that_tell_the_offset_learn_nothing():
    rng = np.random.default_rng(11)
    frames = _frames(rng, MIN_FRAMES - 1, 0.0) + [RangeOffset(0.0, PRIOR_MM, PRIOR_MM)] * 20
    assert learn_range_bias(frames) is None
    assert learn_range_bias(_frames(rng, MIN_FRAMES, 0.0)) is not None
