"""Motion profiles against their definitions: angle, rate and acceleration agree with each
other (numerical derivatives), with the closed forms at known instants, start and end at
rest, and the limit check names the field and limit each violation comes from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tofpose.lab.motion_profile import RampProfile, SineProfile


def _derivative(f, t: np.ndarray) -> np.ndarray:
    h = 1e-5
    return (f(t + h) - f(t - h)) / (2 * h)


@pytest.mark.parametrize(
    "profile",
    [
        SineProfile(5.0, 4.0, 2, start_deg=3.0),
        RampProfile(-10.0, 2.0, 40.0, start_deg=1.0),
        RampProfile(2.5, 0.0, 5.0),
    ],
)
def test_rate_and_acceleration_are_the_derivatives_of_the_angle(profile):
    t = np.linspace(-0.5, profile.duration_s + 0.5, 5001)
    assert np.allclose(
        _derivative(profile.angle_deg_at, t), profile.rate_deg_s_at(t), atol=1e-4
    )  # atol: a * h / 2 where a ramp's acceleration jumps
    # the ramp's acceleration jumps at its phase boundaries: compare away from them
    if isinstance(profile, RampProfile):
        edges = np.array([0.0, profile.ramp_s, profile.ramp_s + profile.hold_s, profile.duration_s])
        t = t[np.min(np.abs(t[:, None] - edges[None, :]), axis=1) > 1e-3]
    assert np.allclose(_derivative(profile.rate_deg_s_at, t), profile.accel_deg_s2_at(t), atol=1e-4)
    for edge in (0.0, profile.duration_s):  # at rest at both ends, and outside
        assert profile.rate_deg_s_at(edge) == pytest.approx(0.0, abs=1e-12)
    assert profile.angle_deg_at(-1.0) == profile.start_deg
    assert profile.angle_deg_at(profile.duration_s + 1.0) == pytest.approx(profile.end_deg)
    for outside in (-1.0, profile.duration_s + 1.0):
        assert profile.accel_deg_s2_at(outside) == pytest.approx(0.0, abs=1e-12)


def test_a_sine_is_the_full_sine_between_its_fades():
    p = SineProfile(5.0, 4.0, 3, start_deg=-2.0)
    w = 2 * math.pi / 4.0
    assert p.duration_s == 20.0 and p.end_deg == pytest.approx(-2.0, abs=1e-12)
    t = np.linspace(4.0, 16.0, 1001)  # the three full-amplitude cycles
    assert np.allclose(p.angle_deg_at(t), -2.0 + 5.0 * np.sin(w * t), atol=1e-12)
    assert np.allclose(p.rate_deg_s_at(t), 5.0 * w * np.cos(w * t), atol=1e-12)
    assert np.allclose(p.accel_deg_s2_at(t), -5.0 * w * w * np.sin(w * t), atol=1e-12)
    assert p.angle_deg_at(5.0) == pytest.approx(3.0)  # start + amplitude a quarter in
    assert p.angle_range_deg == (-7.0, 3.0)
    # the fades: the amplitude grows from 0 to full over the first period
    assert abs(p.angle_deg_at(1.0) + 2.0) < abs(p.angle_deg_at(5.0) + 2.0)
    assert p.accel_deg_s2_at(0.0) == pytest.approx(0.0, abs=1e-12)


def test_a_sines_peaks_cover_its_fades():
    p = SineProfile(5.0, 4.0, 1)
    w = 2 * math.pi / 4.0
    t = np.linspace(0.0, p.duration_s, 400_001)
    assert p.peak_rate_deg_s == pytest.approx(5.0 * w, rel=1e-12)
    assert np.abs(p.rate_deg_s_at(t)).max() <= p.peak_rate_deg_s * (1 + 1e-9)
    dense_peak = np.abs(p.accel_deg_s2_at(t)).max()
    assert p.peak_accel_deg_s2 == pytest.approx(dense_peak, rel=1e-8)
    assert 1.04 < p.peak_accel_deg_s2 / (5.0 * w * w) < 1.06  # the fades' ~5 %


def test_a_ramp_holds_its_rate_and_travels_what_it_says():
    p = RampProfile(-10.0, 2.0, 40.0, start_deg=1.0)
    assert p.ramp_s == 0.25 and p.duration_s == 2.5
    assert p.travel_deg == pytest.approx(-22.5) and p.end_deg == pytest.approx(-21.5)
    assert p.angle_range_deg == (-21.5, 1.0)
    assert np.allclose(p.rate_deg_s_at(np.linspace(0.25, 2.25, 11)), -10.0)
    assert p.accel_deg_s2_at(0.1) == -40.0 and p.accel_deg_s2_at(2.4) == 40.0
    assert p.angle_deg_at(0.25) == pytest.approx(1.0 - 0.5 * 40.0 * 0.25**2)
    assert p.peak_rate_deg_s == 10.0 and p.peak_accel_deg_s2 == 40.0
    assert p.started_at(5.0).end_deg == pytest.approx(-17.5)


LIMITS = {
    "axis": "yaw",
    "min_deg": -170.0,
    "max_deg": 170.0,
    "max_rate_deg_s": 20.0,
    "max_accel_deg_s2": 40.0,
}


def test_within_the_limits_there_is_no_problem():
    assert SineProfile(5.0, 4.0, 1).limit_problems(**LIMITS) == []
    assert RampProfile(20.0, 1.0, 40.0, start_deg=-170.0).limit_problems(**LIMITS) == []


@pytest.mark.parametrize(
    ("profile", "fields", "needles"),
    [
        (
            SineProfile(10.0, 2.0, 1, start_deg=165.0),
            ["amplitude_deg", "amplitude_deg", "period_s"],
            ["soft limits [-170, 170]", "rate limit of 20", "acceleration limit of 40"],
        ),
        # 4 (2 pi / 2)^2 = 39.5 is within 40; the fades take it over
        (SineProfile(4.0, 2.0, 1), ["period_s"], ["peak acceleration 41.4"]),
        (
            RampProfile(25.0, 1.0, 50.0),
            ["rate_deg_s", "accel_deg_s2"],
            ["peak rate 25 deg/s", "peak acceleration 50 deg/s^2"],
        ),
        (
            RampProfile(-10.0, 20.0, 40.0, start_deg=-10.0),
            ["hold_s"],
            ["would sweep [-212.5, -10]", "rate_deg_s -10 for hold_s 20"],
        ),
    ],
)
def test_each_limit_broken_is_named_with_its_field(profile, fields, needles):
    problems = profile.limit_problems(**LIMITS)
    assert [p.field for p in problems] == fields
    for needle, p in zip(needles, problems, strict=False):
        assert needle in p.message, p.message


@pytest.mark.parametrize(
    "make",
    [
        lambda: SineProfile(0.0, 4.0, 1),
        lambda: SineProfile(5.0, -1.0, 1),
        lambda: SineProfile(5.0, 4.0, 0),
        lambda: SineProfile(5.0, 4.0, 1.5),
        lambda: RampProfile(0.0, 1.0, 40.0),
        lambda: RampProfile(5.0, -1.0, 40.0),
        lambda: RampProfile(5.0, 1.0, 0.0),
        lambda: RampProfile(float("nan"), 1.0, 40.0),
    ],
)
def test_meaningless_profiles_are_refused(make):
    with pytest.raises(ValueError):
        make()
