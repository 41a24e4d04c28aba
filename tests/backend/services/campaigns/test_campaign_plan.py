"""Set-point generators and the duration estimate."""

from __future__ import annotations

import pytest

from backend.services.campaigns import campaign_plan as plan


def test_grid_is_the_cartesian_product_yaw_outermost():
    sps = plan.grid(yaw_deg=[0, 5], pitch_deg=[1, 2, 3], rail_mm=10000)
    assert len(sps) == 6
    assert sps[0] == {"yaw": 0.0, "pitch": 1.0, "rail": 10000.0}
    assert sps[3] == {"yaw": 5.0, "pitch": 1.0, "rail": 10000.0}


def test_range_sweep_attitude_steps_stability_and_calibration():
    sweep = plan.range_sweep(rail_start_mm=0, rail_stop_mm=1000, points=3, yaw_deg=2)
    assert sweep == [{"yaw": 2.0, "rail": r} for r in (0.0, 500.0, 1000.0)]
    steps = plan.attitude_steps(axis="roll", steps_deg=[0, 1, -1], rail_mm=5000, roll_deg=9)
    assert steps == [{"rail": 5000.0, "roll": a} for a in (0.0, 1.0, -1.0)]
    assert plan.stability(rail_mm=14303, yaw_deg=None) == [{"rail": 14303.0}]
    cal = plan.calibration(rails_mm=[9000, 12000], amplitude_deg=5)
    assert len(cal) == 18 and {sp["rail"] for sp in cal} == {9000.0, 12000.0}
    # each rotary axis is exercised on its own, in both directions
    for axis in ("yaw", "pitch", "roll"):
        alone = [
            sp
            for sp in cal
            if sp[axis] != 0 and sum(sp[a] != 0 for a in ("yaw", "pitch", "roll")) == 1
        ]
        assert {sp[axis] > 0 for sp in alone} == {True, False}


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: plan.range_sweep(rail_start_mm=0, rail_stop_mm=1, points=1), "at least 2"),
        (lambda: plan.attitude_steps(axis="rail", steps_deg=[1]), "rotary axis"),
        (lambda: plan.attitude_steps(axis="yaw", steps_deg=[]), "at least one"),
        (lambda: plan.calibration(rails_mm=[1000]), "at least 2 rail"),
        (lambda: plan.stability(azimuth_deg=1), "unknown axis"),
    ],
)
def test_generator_errors_name_the_problem(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_duration_adds_moves_settling_and_frames():
    sps = [{"yaw": 10.0}, {"yaw": 10.0, "rail": 1000.0}]
    t = plan.estimate_duration_s(
        sps,
        {"yaw": 0.0, "rail": 0.0},
        {"yaw": 20.0, "rail": 500.0},
        settle_s=1.0,
        frames_per_point=20,
        frame_rate_hz=10.0,
        settle_overhead_s=0.5,
    )
    # point 1: 0.5 s move + 0.5 overhead + 1 settle + 2 s frames; point 2: 2 s rail move ...
    assert t == pytest.approx((0.5 + 0.5 + 1 + 2) + (2.0 + 0.5 + 1 + 2))
