import re

import numpy as np
import pytest

from tofpose import CameraModel, PosePipeline, paper_target
from tofpose.core.geometry import euler_deg_from_rotation
from tofpose.lab.motion_profile import RampProfile, SineProfile
from tofpose.sim.bench import LabGeometry, SimulatedBench
from tofpose.sim.turntable import AxisBusyError, SoftLimitError, Turntable, plan_move


def test_profile_respects_rate_and_acceleration_limits():
    plan = plan_move(0.0, 90.0, 1.0, max_rate=20.0, max_accel=40.0)
    t = np.linspace(0.9, 1.0 + plan.duration_s + 0.1, 4000)
    p = np.array([plan.position(x) for x in t])
    v = np.gradient(p, t)
    a = np.gradient(v, t)
    assert p[0] == 0.0 and p[-1] == 90.0
    assert np.max(np.abs(v)) <= 20.0 * 1.01
    assert np.percentile(np.abs(a), 99) <= 40.0 * 1.05
    assert plan.duration_s == pytest.approx(90 / 20 + 20 / 40)  # trapezoid: d/v + v/a


def test_short_move_is_triangular():
    plan = plan_move(0.0, 1.0, 0.0, max_rate=20.0, max_accel=40.0)
    assert plan.t_flat_s == 0.0 and plan.rate < 20.0
    assert plan.position(plan.duration_s) == 1.0


def test_soft_limits_reject_before_any_axis_moves():
    tt = Turntable()
    with pytest.raises(SoftLimitError, match="pitch set-point 75 deg is outside"):
        tt.move_to({"roll": 10.0, "pitch": 75.0}, 0.0)
    assert tt.target_position()["roll"] == 0.0
    with pytest.raises(ValueError, match="unknown axis 'tilt'"):
        tt.move_to({"tilt": 1.0}, 0.0)


def test_settling_encoders_and_stop():
    tt = Turntable(seed=3)
    done = tt.move_to({"yaw": 30.0}, 0.0)
    assert tt.is_busy(done / 2) and not tt.is_settled(done / 2)
    t_settled = tt.settle_time(0.0)
    assert t_settled >= done and tt.is_settled(t_settled)
    enc = tt.encoder_position(t_settled + 1.0)
    assert enc["yaw"] == pytest.approx(30.0, abs=1e-3)
    assert enc["yaw"] / 1e-4 == pytest.approx(round(enc["yaw"] / 1e-4))  # quantised
    tt.move_to({"roll": 90.0}, 10.0)
    tt.stop(11.0)
    frozen = tt.true_position(11.0)["roll"]
    assert 0 < frozen < 90 and tt.true_position(20.0)["roll"] == pytest.approx(frozen)


@pytest.mark.parametrize("theta_deg", [20.3, -36.0])
def test_inner_axis_roll_rolls_the_measured_target(theta_deg):
    """Rolling the camera by theta about its boresight rolls the target by -theta in the
    camera frame (the paper's Fig. 11 shows the same sign flip)."""
    bench = SimulatedBench(geometry=LabGeometry(target_distance_mm=2000.0), seed=5)
    pipe = PosePipeline(CameraModel(), paper_target())
    bench.turntable.move_to({"roll": theta_deg}, 0.0)
    t = bench.turntable.settle_time(0.0)
    bf = bench.capture(t)
    r = pipe.process(bf.frame.gray, bf.frame.distance_mm)
    assert r.ok
    roll_truth = euler_deg_from_rotation(bf.T_lab_truth.R)[2]
    assert roll_truth == pytest.approx(-theta_deg, abs=1e-3)
    assert r.euler_deg[2] == pytest.approx(-theta_deg, abs=0.1)


def test_mount_error_separates_world_from_lab_truth():
    from tofpose.core.geometry import RigidTransform, rotation_angle_deg

    geom = LabGeometry(mount_error=RigidTransform.from_euler_deg(0.3, 0, 0, (2, 0, 0)))
    pos = {"yaw": 0.0, "pitch": 0.0, "roll": 0.0, "rail": 0.0}
    true, lab = geom.T_camera_target(pos, true=True), geom.T_camera_target(pos, true=False)
    assert rotation_angle_deg(true.R, lab.R) == pytest.approx(0.3, abs=1e-9)


def test_an_axis_follows_a_sine_profile_within_its_limits():
    """The yaw encoders read the profile's angle (within encoder noise and resolution) at
    every time, the finite-difference rate of the readings follows the profile's rate,
    and the motion stays within the axis' rate limit; the other axes stay put."""
    tt = Turntable(seed=4)
    tt.move_to({"yaw": 10.0}, 0.0)
    t0 = tt.settle_time(0.0)
    started = tt.run_profile("yaw", SineProfile(5.0, 4.0, 1), t0)
    assert started.start_deg == pytest.approx(10.0, abs=1e-3)
    assert tt.running_profile(t0 + 1.0)[0] == "yaw" and tt.is_busy(t0 + 1.0)
    t = t0 + np.arange(0.0, started.duration_s, 0.01)
    enc = np.array([tt.encoder_position(x)["yaw"] for x in t])
    assert np.abs(enc - started.angle_deg_at(t - t0)).max() < 1.5e-3  # noise 2e-4, lsb 1e-4
    rate = np.gradient(enc, t)
    assert np.sqrt(np.mean((rate - started.rate_deg_s_at(t - t0)) ** 2)) < 0.05
    assert np.abs(rate).max() <= tt.axes["yaw"].max_rate
    assert tt.true_position(t0 + 5.0)["pitch"] == 0.0
    end = t0 + started.duration_s
    assert tt.running_profile(end + 0.01) is None and not tt.is_busy(end + 0.01)
    assert tt.encoder_position(end + 1.0)["yaw"] == pytest.approx(10.0, abs=1e-3)


def test_a_ramp_travels_at_its_rate_then_rests():
    tt = Turntable(seed=5)
    started = tt.run_profile("roll", RampProfile(-15.0, 2.0, 30.0), 1.0)
    mid = 1.0 + started.ramp_s + 1.0
    dt = 0.1
    rate = (tt.true_position(mid + dt)["roll"] - tt.true_position(mid)["roll"]) / dt
    assert rate == pytest.approx(-15.0)
    assert tt.target_position()["roll"] == pytest.approx(-15.0 * 2.5)
    assert tt.true_position(1.0 + started.duration_s)["roll"] == pytest.approx(-37.5)


@pytest.mark.parametrize(
    ("profile", "needle"),
    [
        (SineProfile(70.0, 30.0, 1), "soft limits [-60, 60]"),
        (SineProfile(10.0, 2.0, 1), "rate limit of 20"),
        (SineProfile(4.0, 2.0, 1), "acceleration limit of 40"),
        (RampProfile(10.0, 1.0, 80.0), "acceleration limit of 40"),
    ],
)
def test_a_profile_beyond_a_limit_is_refused_and_nothing_moves(profile, needle):
    tt = Turntable()
    with pytest.raises(SoftLimitError, match=re.escape(needle)):
        tt.run_profile("pitch", profile, 0.0)
    assert tt.running_profile(0.5) is None and tt.true_position(5.0)["pitch"] == 0.0


def test_a_profile_needs_a_rotary_axis_at_rest_and_stop_ends_it():
    tt = Turntable()
    with pytest.raises(ValueError, match="rotary axes"):
        tt.run_profile("rail", SineProfile(1.0, 4.0, 1), 0.0)
    done = tt.move_to({"yaw": 20.0}, 0.0)
    with pytest.raises(AxisBusyError, match="still moving"):
        tt.run_profile("yaw", SineProfile(1.0, 4.0, 1), done / 2)
    t0 = done + 1.0
    tt.run_profile("yaw", SineProfile(5.0, 4.0, 2), t0)
    with pytest.raises(AxisBusyError, match="running a motion profile"):
        tt.move_to({"yaw": 0.0}, t0 + 1.0)
    tt.move_to({"pitch": 1.0}, t0 + 1.0)  # another axis may move meanwhile
    tt.stop(t0 + 5.3)
    here = tt.true_position(t0 + 5.3)["yaw"]
    assert abs(here - 20.0) > 1.0  # stopped mid-swing, where it was
    assert tt.running_profile(t0 + 5.4) is None and tt.is_stopped()
    assert tt.true_position(t0 + 9.0)["yaw"] == pytest.approx(here)
