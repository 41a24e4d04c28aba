"""The relative-state filter (``tofpose.lab.relative_state``) against known truth: its own
process model simulated exactly (the covariance must hold: NEES), and poses the pipeline
measures on frames ``tofpose.sim`` renders of a tumbling and a slewing target."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import facing_pose, render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.config import PersistenceConfig
from tofpose.core.geometry import RigidTransform
from tofpose.lab.relative_state import RelativeStateConfig, RelativeStateFilter, state_error

SIGMA_RAD, SIGMA_MM = math.radians(0.1), 1.0
POSE_COV = np.diag([SIGMA_RAD**2] * 3 + [SIGMA_MM**2] * 3)


def _process(cfg, n, dt, rng, w0=(2.0, -5.0, 3.0), v0=(10.0, -5.0, 20.0), substeps=20):
    """Truth drawn from the filter's model, integrated on its own (Euler-Maruyama on
    ``substeps`` per frame interval: ``dR/dt = [w]x R``, ``dt/dt = v``, ``dw/dt`` white of
    density q_a, ``dv/dt = w x v`` plus white of density ``q_l I + q_a (|t|^2 I - t t^T)``;
    with ``angular_jerk_psd`` also ``dw/dt = a + white``, ``da/dt`` white of density q_j
    and ``dv/dt`` gains ``a x t``) and noisy poses of it: yields (time, R, t, w, v,
    measured R, measured t)."""
    R, t = np.eye(3), np.array([0.0, 0.0, 3000.0])
    w, v, a = np.radians(w0), np.array(v0, float), np.zeros(3)
    h = dt / substeps
    for k in range(n):
        for _ in range(substeps if k else 0):
            lin = cfg.linear_accel_psd * np.eye(3) + cfg.angular_accel_psd * (
                t @ t * np.eye(3) - np.outer(t, t)
            )
            R = Rotation.from_rotvec(w * h).as_matrix() @ R
            t = t + v * h
            v = v + (np.cross(w, v) + np.cross(a, t)) * h
            v = v + rng.multivariate_normal(np.zeros(3), lin * h)
            w = w + a * h + rng.normal(0.0, math.sqrt(cfg.angular_accel_psd * h), 3)
            if cfg.angular_jerk_psd is not None:
                a = a + rng.normal(0.0, math.sqrt(cfg.angular_jerk_psd * h), 3)
        Rm = Rotation.from_rotvec(rng.normal(0, SIGMA_RAD, 3)).as_matrix() @ R
        yield k * dt, R, t, w, v, Rm, t + rng.normal(0, SIGMA_MM, 3)


def _fed(cfg, n, n_fed, seed, w0, v0):
    """A filter given the first ``n_fed`` of ``n`` poses of ``_process``, and all n."""
    f = RelativeStateFilter(cfg)
    frames = list(_process(cfg, n, 0.1, np.random.default_rng(seed), w0, v0))
    for tt, *_, Rm, tm in frames[:n_fed]:
        f.update(tt, Rm, tm, POSE_COV)
    return f, frames


CONSTANT_TWIST = RelativeStateConfig(
    angular_accel_psd=math.radians(5) ** 2, linear_accel_psd=50.0**2
)
CONSTANT_ACCELERATION = RelativeStateConfig.constant_acceleration(
    angular_jerk_psd=math.radians(1) ** 2, linear_accel_psd=50.0**2
)


@pytest.mark.parametrize("cfg", [CONSTANT_TWIST, CONSTANT_ACCELERATION], ids=["twist", "accel"])
def test_the_covariance_holds_on_the_filters_own_process(cfg):
    f, nees = RelativeStateFilter(cfg), []
    frames = _process(cfg, 400, 0.1, np.random.default_rng(0))
    for k, (tt, R, t, w, v, Rm, tm) in enumerate(frames):
        s = f.update(tt, Rm, tm, POSE_COV)
        assert s.status == ("initialised" if k == 0 else "updated")
        if k > 50:  # converged from its start at rest
            e = state_error(s, R, t, w, v)
            nees.append(e @ np.linalg.solve(s.covariance, e))
    assert 9.0 < np.mean(nees) < 16.0  # 12 for a consistent covariance of the 12 reported


def test_a_wrong_pose_is_rejected_and_does_not_drag_the_state():
    cfg = RelativeStateConfig(angular_accel_psd=math.radians(1) ** 2, linear_accel_psd=10.0**2)
    f, frames = _fed(cfg, 60, 40, seed=1, w0=(0, 3, 0), v0=(0, 0, 0))
    tt, R, t, w, v, Rm, tm = frames[40]
    bad = Rotation.from_rotvec(np.radians([0, 5.0, 0])).as_matrix() @ Rm  # 5 deg off
    s = f.update(tt, bad, tm, POSE_COV)
    assert s.status == "rejected" and s.n_rejected == 1 and s.innovation_d2 > cfg.gate_chi2
    assert np.degrees(np.linalg.norm(state_error(s, R, t, w, v)[:3])) < 0.3
    s = f.update(frames[41][0], *frames[41][5:], POSE_COV)
    assert s.status == "updated" and s.n_rejected == 0


def test_a_target_that_jumped_is_reacquired_after_consistent_rejections():
    cfg = RelativeStateConfig(angular_accel_psd=math.radians(1) ** 2, linear_accel_psd=10.0**2)
    f = RelativeStateFilter(cfg)
    jump = Rotation.from_rotvec(np.radians([0, 20.0, 0])).as_matrix()
    statuses = []
    s = None
    for k, (tt, R, t, _w, _v, Rm, tm) in enumerate(
        _process(cfg, 60, 0.1, np.random.default_rng(2), (0, 2, 0), (0, 0, 0))
    ):
        if k >= 30:  # re-placed: every pose from here on is 20 deg and 300 mm away
            Rm, tm, R, t = jump @ Rm, tm + 300.0, jump @ R, t + 300.0
        s = f.update(tt, Rm, tm, POSE_COV)
        statuses.append(s.status)
    assert statuses[30:33] == ["rejected", "rejected", "reset"]
    assert set(statuses[34:]) == {"updated"}
    assert np.degrees(np.linalg.norm(state_error(s, R, t, _w, _v)[:3])) < 0.3


def test_a_two_second_dropout_is_bridged_and_the_state_can_be_asked_ahead():
    cfg = RelativeStateConfig(angular_accel_psd=math.radians(2) ** 2, linear_accel_psd=20.0**2)
    f, frames = _fed(cfg, 100, 50, seed=3, w0=(0, 6, 0), v0=(5, 0, 0))
    ahead = f.state_at(frames[55][0])  # the controller's time, 0.5 s later
    for tt, *_ in frames[50:70]:  # 2 s without a pose
        s = f.predict(tt)
        assert s.status == "predicted"
    assert f.state_at(frames[69][0]).time_s == pytest.approx(frames[69][0])
    tt, R, t, w, v, Rm, tm = frames[69]
    e = state_error(s, R, t, w, v)
    assert e @ np.linalg.solve(s.covariance, e) < 32.9  # chi2_12 at 0.999
    s = f.update(frames[70][0], *frames[70][5:], POSE_COV)
    assert s.status == "updated"  # reacquired without a reset
    # asking ahead is prediction: it matches truth at that time within its covariance
    _, R55, t55, w55, v55, *_ = frames[55]
    e = state_error(ahead, R55, t55, w55, v55)
    assert e @ np.linalg.solve(ahead.covariance, e) < 32.9


def test_a_dropout_longer_than_the_gap_limit_restarts_the_filter_at_the_next_pose():
    """Frames without a pose are predicted one by one (as ``estimate --filter`` does);
    the gap still counts from the last pose fused."""
    cfg = RelativeStateConfig(max_gap_s=10.0)
    f, frames = _fed(cfg, 10, 10, seed=4, w0=(0, 3, 0), v0=(0, 0, 0))
    for k in range(1, 121):  # 12 s of frames without a pose
        f.predict(0.9 + 0.1 * k)
    s = f.update(13.0, *frames[-1][5:], POSE_COV)
    assert s.status == "initialised"
    assert np.all(s.angular_rate_deg_s == 0.0)  # started again from the pose alone
    f2, _ = _fed(cfg, 10, 10, seed=4, w0=(0, 3, 0), v0=(0, 0, 0))
    for k in range(1, 51):  # 5 s: within the limit, the prediction is kept
        f2.predict(0.9 + 0.1 * k)
    assert f2.update(5.95, *frames[-1][5:], POSE_COV).status in ("updated", "rejected")


def test_bad_input_is_refused_with_a_reason():
    f = RelativeStateFilter()
    with pytest.raises(RuntimeError, match="starts with a pose"):
        f.state()
    f.update(1.0, np.eye(3), np.zeros(3), POSE_COV)
    with pytest.raises(ValueError, match="time order"):
        f.update(0.5, np.eye(3), np.zeros(3), POSE_COV)
    with pytest.raises(ValueError, match="6 x 6"):
        f.update(2.0, np.eye(3), np.zeros(3), np.eye(3))


def _rendered(truth, n, cfg):
    """Poses the pipeline measures (single-frame persistence: combining frames while
    the target moves lags the pose) on frames rendered at 10 Hz; the filter's rate error
    (deg/s) and NEES after 4 s, and the peak true rate (deg/s)."""
    cam, cat = CameraModel(), paper_target()
    pipe = PosePipeline(cam, cat, PipelineConfig(persistence=PersistenceConfig(1, 1)))
    f, errors, nees, peak, missed = RelativeStateFilter(cfg), [], [], 0.0, 0
    t0 = facing_pose(3000.0, 2, -3, 5)
    for k in range(n):
        tt = 0.1 * k
        R, w = truth(tt, t0.R)
        frame = render(RigidTransform(R, t0.t_mm), seed=k)
        r = pipe.process(frame.gray, frame.distance_mm, tt)
        if not r.ok:  # a frame without a pose (the fit refused it): the filter predicts
            missed += 1
            s = f.predict(tt)
            continue
        s = f.update(tt, r.R, r.t_mm, r.covariance)
        peak = max(peak, math.degrees(np.linalg.norm(w)))
        if tt > 4.0:
            e = state_error(s, R, t0.t_mm, w, np.zeros(3))
            errors.append(np.linalg.norm(np.degrees(e[6:9])))
            nees.append(e @ np.linalg.solve(s.covariance, e))
    assert missed <= 0.1 * n
    return np.sqrt(np.mean(np.square(errors))), np.mean(nees), peak


def test_a_tumbling_target_rendered_by_the_simulator_gives_its_rate():
    w = np.radians([0.0, 8.0, 3.0])  # 8.5 deg/s about a fixed axis in the camera frame
    cfg = RelativeStateConfig(angular_accel_psd=math.radians(1.0) ** 2, linear_accel_psd=100.0)
    rms, nees, peak = _rendered(
        lambda tt, R0: (Rotation.from_rotvec(w * tt).as_matrix() @ R0, w), 80, cfg
    )
    assert rms < 0.05 * peak  # 0.3 deg/s
    # the pipeline's covariance at 3 m is wider than its errors (docs/results.md), so the
    # filter's is too; it must not claim less than it knows
    assert 1.0 < nees < 18.0


def _sine_slew(cfg):
    amp, period = math.radians(5.0), 4.0  # the turntable's sine of the done-when
    axis = np.array([0.0, 1.0, 0.0])

    def truth(tt, R0):
        angle = amp * math.sin(2 * math.pi * tt / period)
        rate = amp * 2 * math.pi / period * math.cos(2 * math.pi * tt / period)
        return Rotation.from_rotvec(axis * angle).as_matrix() @ R0, axis * rate

    return _rendered(truth, 120, cfg)


def test_a_sine_slew_rendered_by_the_simulator_gives_its_rate():
    amp, period = math.radians(5.0), 4.0
    alpha = amp * (2 * math.pi / period) ** 2
    cfg = RelativeStateConfig(angular_accel_psd=alpha**2 * period / 10, linear_accel_psd=100.0)
    rms, nees, peak = _sine_slew(cfg)
    assert rms < 0.15 * peak  # 0.8 deg/s of 7.9 measured
    assert 1.0 < nees < 18.0


def test_the_constant_acceleration_model_follows_a_target_turning_about_itself():
    """The sine above about the target's own origin (a tumble's case: the twist's linear
    acceleration b = -a x t is at the far end of what the model assumes): as close as
    the constant-twist model's best tuning for this very motion (0.77 vs 0.8 deg/s)."""
    rms, nees, peak = _sine_slew(RelativeStateConfig.constant_acceleration(linear_accel_psd=100.0))
    assert rms < 0.12 * peak, (rms, peak)
    assert 1.0 < nees < 18.0


def _on_the_table(cfg: RelativeStateConfig, move, seconds: float, dt_s: float):
    """The simulated lab with the camera on the turntable, ``move(turntable)`` started
    at 1 s; frames every ``dt_s`` rendered with the sensor's motion artefacts, each measured
    by a pipeline as the server runs it and given to a filter of ``cfg``. Yields (time,
    filter state, true camera-frame rate rad/s) per frame."""
    from backend.drivers.sim import make_sim_world
    from tofpose.sim.render import render_frame

    bench = make_sim_world().bench
    pipe = PosePipeline(bench.camera, bench.scene.catalog)
    f = RelativeStateFilter(cfg)
    move(bench.turntable)
    for k in range(int(seconds / dt_s)):
        tt = k * dt_s
        T, _, _ = bench.poses_at(tt)
        frame = render_frame(
            bench.camera,
            bench.scene,
            T,
            bench.sensor,
            bench.rng,
            time_s=tt,
            subframe_poses=bench.subframe_poses(tt, T),
        )
        r = pipe.process(frame.gray, frame.distance_mm, tt)
        s = f.step(tt, *((r.R, r.t_mm, r.covariance) if r.ok else (None,) * 3))
        ahead, _, _ = bench.poses_at(tt + 1e-3)
        yield tt, s, Rotation.from_matrix(ahead.R @ T.R.T).as_rotvec() / 1e-3


def test_a_turntable_sine_gives_its_rate_within_a_tenth_of_its_peak():
    """The issue's done-when on the simulated lab: the turntable's yaw runs a sine of 5
    deg and 4 s (fades of one period each side) at 10 Hz; the yaw rate's RMS error once
    converged (after 5 s) within 10 % of the peak rate (7.85 deg/s) with the server's
    model; the constant-twist model lags this slew by more (measured 1.12 deg/s, 14 %)."""
    from tofpose.lab.motion_profile import SineProfile

    profile = SineProfile(5.0, 4.0, 2)
    frames = _on_the_table(
        RelativeStateConfig.constant_acceleration(),
        lambda table: table.run_profile("yaw", profile, 1.0),
        18.0,
        0.1,
    )
    errors = [s.angular_rate_deg_s[1] - math.degrees(w[1]) for tt, s, w in frames if tt > 5.0]
    rms = float(np.sqrt(np.mean(np.square(errors))))
    assert rms < 0.10 * profile.peak_rate_deg_s, (rms, profile.peak_rate_deg_s)


def _turn(dt_s: float, cfg: RelativeStateConfig | None = None):
    """The turntable's yaw turned 20 deg at its full rate (20 deg/s) and acceleration (40
    deg/s^2) with the camera on it, frames every ``dt_s``: the filter's statuses and
    (filter, true) yaw rates at each frame."""
    frames = _on_the_table(
        cfg or RelativeStateConfig(), lambda table: table.move_to({"yaw": 20.0}, 1.0), 4.0, dt_s
    )
    return [(tt, s.status, s.angular_rate_deg_s[1], math.degrees(w[1])) for tt, s, w in frames]


@pytest.mark.parametrize("model", ["twist", "accel"])
@pytest.mark.parametrize("dt_s", [0.1, 0.3])
def test_a_fast_turn_of_the_camera_is_followed_not_gated(dt_s, model):
    """The camera turns about the table's axis, so the target's origin swings round it
    (~700 mm/s at 2 m): a constant-velocity model gated every pose of the turn (the e2e
    defect); the constant twist follows it. At 0.3 s between frames (a loaded server) the
    turn's start and end are steps of 12 deg/s in one interval: the rate has caught up
    by the second frame at full rate."""
    cfg = RelativeStateConfig.constant_acceleration() if model == "accel" else None
    # the acceleration state carries the 40 deg/s^2 ramp past its end for a while: at
    # 0.3 s between frames it overshoots by ~2.3 deg/s at the second frame at full rate
    tolerance = 2.0 if model == "twist" else 2.5
    out = _turn(dt_s, cfg)
    assert all(st in ("initialised", "updated") for _, st, _, _ in out), out
    cruise = [abs(w - w_true) for _, _, w, w_true in out if abs(w_true) > 19.9]
    assert len(cruise) >= 2 and max(cruise[1:]) < tolerance, out  # of 20 deg/s, after a frame


@pytest.mark.parametrize("angle_rad", [1e-9, 1e-5, 0.1, 1.0, 3.0, math.pi - 1e-4])
def test_the_filters_rotation_maps_agree_with_scipy(angle_rad):
    from tofpose.lab.relative_state import _exp, _log

    rng = np.random.default_rng(1)
    for _ in range(20):
        w = rng.normal(size=3)
        w *= angle_rad / np.linalg.norm(w)
        R = Rotation.from_rotvec(w).as_matrix()
        np.testing.assert_allclose(_exp(w), R, atol=1e-12)
        np.testing.assert_allclose(_log(R), w, rtol=1e-6, atol=1e-15)
