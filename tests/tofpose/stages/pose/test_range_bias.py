"""The range bias learned over a recording's frames: each frame's offset likelihood (its
posterior with the prior divided out) and the maximum-likelihood spread of the offsets,
against offsets drawn with a known spread."""

import numpy as np
import pytest

from tofpose.stages.pose.range_bias import MIN_FRAMES, learn_range_bias
from tofpose.stages.pose.records import NO_RANGE_OFFSET, RangeOffset

PRIOR_MM = 15.0


def _posterior(m_mm: float, v_mm2: float, prior_mm: float = PRIOR_MM) -> RangeOffset:
    """The RangeOffset a fit reports whose frame alone says N(m, v) of the offset, under
    the prior N(0, prior^2): the product of the two Gaussians."""
    precision = 1.0 / v_mm2 + 1.0 / prior_mm**2
    return RangeOffset(m_mm / v_mm2 / precision, float(np.sqrt(1.0 / precision)), prior_mm)


def _frames(rng, n: int, tau_mm: float, mean_mm: float = 0.0) -> list[RangeOffset]:
    """n frames whose true offsets spread by ``tau_mm`` about ``mean_mm``, each measured
    with its own noise (sigma 1-6 mm, as the image scale tells it at 2-8 m)."""
    sd = rng.uniform(1.0, 6.0, n)
    true = rng.normal(mean_mm, tau_mm, n) if tau_mm > 0 else np.full(n, mean_mm)
    return [_posterior(t + rng.normal(0.0, s), s**2) for t, s in zip(true, sd, strict=True)]


def test_a_frames_likelihood_is_its_posterior_with_the_prior_divided_out():
    m, v = _posterior(7.0, 4.0).likelihood()
    assert m == pytest.approx(7.0)
    assert v == pytest.approx(4.0)


def test_a_frame_that_tells_nothing_has_no_likelihood():
    assert RangeOffset(0.0, PRIOR_MM, PRIOR_MM).likelihood() is None  # posterior = prior
    assert NO_RANGE_OFFSET.likelihood() is None  # no offset modelled
    assert RangeOffset(0.0, 3.0, 0.0).likelihood() is None  # no prior to divide out


@pytest.mark.parametrize("tau_mm", [0.0, 4.0, 10.0])
def test_the_learned_spread_is_the_drawn_one(tau_mm):
    rng = np.random.default_rng([7, int(tau_mm)])
    learned = learn_range_bias(_frames(rng, 400, tau_mm))
    assert learned is not None
    assert learned.n_frames == 400
    # the estimate's own standard error decides how close: 3 of them
    assert abs(learned.tau_mm**2 - tau_mm**2) < 3 * learned.tau2_se_mm2 + 0.5
    # the prior it gives covers the spread: its upper one-sigma value
    assert learned.sigma_mm >= learned.tau_mm
    assert learned.sigma_mm**2 == pytest.approx(learned.tau_mm**2 + learned.tau2_se_mm2)


def test_a_calibrated_cameras_frames_shrink_the_prior_far_below_the_uncalibrated_one():
    learned = learn_range_bias(_frames(np.random.default_rng(8), 64, 0.0))
    assert learned is not None
    assert learned.sigma_mm < 0.25 * PRIOR_MM


def test_a_constant_offset_is_covered_by_the_spread_about_zero():
    """A camera whose offset is 9 mm on every frame: the spread about 0 is ~9 mm (the
    prior is not re-centred), and the mean reads it."""
    learned = learn_range_bias(_frames(np.random.default_rng(9), 200, 0.0, mean_mm=9.0))
    assert learned is not None
    assert 7.5 < learned.tau_mm < 10.5
    assert learned.mean_mm == pytest.approx(9.0, abs=1.0)


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
