"""Relative state and latency on the simulated lab (docs/results.md, "Relative state and
latency"): the filter's rate accuracy on the turntable's sine, the latency fit finding a
programmed capture-to-processing delay, and the filter's cost per frame.

The turntable's yaw runs the done-when's sine (5 deg, 4 s, fades of one period each side,
two cycles between) with the camera on it; frames are rendered with the sensor's motion
artefacts at 10 and 30 Hz and measured by a pipeline configured as the server configures
it for the simulated camera (``SERVER_PIPELINE``: persistence and tracking on, no common
range-bias prior for a sensor without systematic errors). Per seed and frame rate:

- rate: each model (constant twist; constant acceleration, the server's) on those poses:
  RMS of the camera-y rate error after 5 s (the sine's peak 7.85 deg/s), and the mean
  NEES of the 12 reported states against the truth;
- latency: the poses stamped ``d`` late (a driver that stamps on arrival after a transfer
  and processing delay d), the reference the lab's (encoders and nominal geometry) at the
  stamps, as a dynamic campaign stores it; ``tofpose.lab.dynamics.fit_latency`` should find
  ``d``: a frame's stamp is the middle of its four phase sub-frames (the simulator's
  convention since 2026-12-08; before, it was the first sub-frame's start and the fit
  read ``d`` less 1.5 sub-frame periods). What it finds beyond ``d`` on frames with
  motion artefacts is their rate-proportional attitude bias read as a time offset;
- cost: the filter's update, median and p95 over every frame, beside the pipeline's time
  on the same frames.

Run: ``python bench/dynamics.py [--seeds 2] [--seconds 18]``
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import med_p95, single_core, table  # noqa: E402
from tofpose.config import PersistenceConfig, TrackingConfig  # noqa: E402
from tofpose.lab.dynamics import fit_latency  # noqa: E402
from tofpose.lab.motion_models import TwoModelRelativeState  # noqa: E402
from tofpose.lab.motion_profile import SineProfile  # noqa: E402
from tofpose.lab.relative_state import (  # noqa: E402
    RelativeStateConfig,
    RelativeStateFilter,
    state_error,
)
from tofpose.lab.smoothing import smoothed_states  # noqa: E402
from tofpose.pipeline import PipelineConfig, PosePipeline  # noqa: E402
from tofpose.sim.render import render_frame  # noqa: E402

DELAYS_S = (0.0, 0.040, 0.100)
#: backend.app._pipeline_config for the simulated camera (TOFPOSE_TRACKING on by default)
SERVER_PIPELINE = PipelineConfig(tracking=TrackingConfig(enabled=True), range_bias_sigma_mm=0.0)
#: each motion model's filter, built fresh per run
MODELS = {
    "constant twist": lambda: RelativeStateFilter(RelativeStateConfig()),
    "constant acceleration (server)": lambda: RelativeStateFilter(
        RelativeStateConfig.constant_acceleration()
    ),
    "two models (estimate --filter --causal)": TwoModelRelativeState,
}
#: the tumble table's row of ``tofpose.lab.smoothing`` (all the poses, both ways)
SMOOTHED = "two models, smoothed (estimate --filter)"


def measure(seed: int, rate_hz: float, seconds: float):
    """Frames of the sine rendered and measured: a dict of arrays (time, ok, R, t, cov,
    true R, t, w, v; pipeline ms) and the sine's peak rate (deg/s)."""
    from backend.drivers.sim import make_sim_world

    bench = make_sim_world(seed=seed).bench
    pipe = PosePipeline(bench.camera, bench.scene.catalog, SERVER_PIPELINE)
    profile = SineProfile(5.0, 4.0, 2)
    bench.turntable.run_profile("yaw", profile, 1.0)
    rows = []
    for k in tqdm(
        range(int(seconds * rate_hz)),
        desc=f"seed {seed}, {rate_hz:g} Hz",
        leave=False,
        file=sys.stderr,
    ):
        tt = k / rate_hz
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
        t0 = time.perf_counter()
        r = pipe.process(frame.gray, frame.distance_mm, tt)
        ms = (time.perf_counter() - t0) * 1e3
        h = 1e-3
        ahead, _, _ = bench.poses_at(tt + h)
        behind, _, _ = bench.poses_at(tt - h)
        w = Rotation.from_matrix(ahead.R @ behind.R.T).as_rotvec() / (2 * h)
        v = (ahead.t_mm - behind.t_mm) / (2 * h)
        rows.append(
            (
                tt,
                r.ok,
                r.R if r.ok else np.eye(3),
                r.t_mm if r.ok else np.zeros(3),
                r.covariance if r.ok else np.eye(6),
                T.R,
                T.t_mm,
                w,
                v,
                ms,
            )
        )
    names = ("t", "ok", "R", "tm", "cov", "Rt", "tt", "w", "v", "ms")
    data = {n: np.array([row[i] for row in rows]) for i, n in enumerate(names)}
    return data, profile.peak_rate_deg_s


def run_filter(make_filter, d: dict):
    """(camera-y rate RMS error after 5 s deg/s, mean NEES, update times in us) of the
    filter ``make_filter()`` builds."""
    f, errs, nees, us = make_filter(), [], [], []
    for i, tt in enumerate(d["t"]):
        t0 = time.perf_counter()
        s = f.step(tt, *((d["R"][i], d["tm"][i], d["cov"][i]) if d["ok"][i] else (None,) * 3))
        us.append((time.perf_counter() - t0) * 1e6)
        if tt > 5.0:
            e = state_error(s, d["Rt"][i], d["tt"][i], d["w"][i], d["v"][i])
            errs.append(np.degrees(e[7]))
            nees.append(e @ np.linalg.solve(s.covariance, e))
    return float(np.sqrt(np.mean(np.square(errs)))), float(np.mean(nees)), us


def tumble_errors(seed: int, seconds: float = 8.0, rate_hz: float = 10.0) -> dict[str, float]:
    """A target tumbling freely: a constant rate of 3-8 deg/s about a random axis through
    its centre, 3-8 m away, frames rendered at ``rate_hz`` and measured as ``tofpose
    estimate --filter`` measures them (each pose from its own frame:
    ``PersistenceConfig.single_frame``; combining frames lags the tumble); per model
    (causal, and the smoother of ``estimate --filter``), the rate's RMS error as a
    fraction of the rate after 3 s (key: the model) and over all frames (the model +
    ", all")."""
    from scipy.spatial.transform import Rotation

    from tofpose import CameraModel, paper_target
    from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel
    from tofpose.sim.scene import TargetScene

    cam, cat = CameraModel(), paper_target()
    rng = np.random.default_rng([seed, 77])
    z = rng.uniform(3000, 8000)
    rate = np.radians(rng.uniform(3, 8))
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R0 = rotation_from_euler_deg(*rng.uniform(-10, 10, 3)) @ R_FACING
    centre = np.array([rng.uniform(-200, 200), rng.uniform(-150, 150), z])
    pipe = PosePipeline(cam, cat, PipelineConfig(persistence=PersistenceConfig.single_frame()))
    filters = {m: make() for m, make in MODELS.items()}
    states: dict[str, list] = {m: [] for m in (*MODELS, SMOOTHED)}
    times, poses, truth = [], [], []
    for k in range(int(seconds * rate_hz)):
        t = k / rate_hz
        R = Rotation.from_rotvec(axis * rate * t).as_matrix() @ R0
        T = RigidTransform(R, centre - R @ cat.positions_mm.mean(axis=0))
        f = render_frame(cam, TargetScene(cat), T, SensorModel(), rng)
        r = pipe.process(f.gray, f.distance_mm, t)
        pose = (r.R, r.t_mm, r.covariance) if r.ok else None
        for m, filt in filters.items():
            states[m].append(filt.step(t, *(pose or (None, None, None))))
        times.append(t)
        poses.append(pose)
        truth.append(axis * rate)
    states[SMOOTHED] = smoothed_states(times, poses)
    out = {}
    for m, st in states.items():
        e = [
            (t, np.radians(s.angular_rate_deg_s) - w)
            for t, s, w in zip(times, st, truth, strict=True)
            if s is not None
        ]
        for key, after in ((m, 3.0), (f"{m}, all", 0.0)):
            sq = [np.sum(np.square(d)) for t, d in e if t >= after]
            out[key] = float(np.sqrt(np.mean(sq)) / rate)
    return out


def latency(seed: int, artefacts: bool, delays_s, seconds: float = 12.0):
    """The latency fit on 10 Hz poses of the sine (the server's pipeline) stamped late by
    each programmed delay, against the lab reference (encoders and nominal geometry) at the
    stamps, as a dynamic campaign stores it; frames rendered with or without the sensor's
    motion artefacts. Without them a frame is the scene at its stamp, so the fit must find
    the programmed delay."""
    from backend.drivers.sim import make_sim_world

    bench = make_sim_world(seed=seed).bench
    bench.sensor = replace(bench.sensor, motion_artefacts=artefacts)
    pipe = PosePipeline(bench.camera, bench.scene.catalog, SERVER_PIPELINE)
    bench.turntable.run_profile("yaw", SineProfile(5.0, 4.0, 1), 1.0)
    ts, Rs = [], []
    for k in range(int(seconds * 10)):
        tt = 0.1 * k
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
        if r.ok:
            ts.append(tt)
            Rs.append(r.R)
    out = []
    for delay in delays_s:
        stamps = np.array(ts) + delay
        ref_t = np.arange(stamps[0] - 0.6, stamps[-1] + 0.6, 0.02)
        R_ref = np.array([bench.poses_at(float(x))[1].R for x in ref_t])
        out.append(fit_latency(stamps, np.array(Rs), ref_t, R_ref))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=18.0)
    args = ap.parse_args()
    single_core()
    rate_rows, lat_rows, cost = [], [], {m: [] for m in MODELS}
    pipe_ms = []
    for rate_hz in (10.0, 30.0):
        per_model = {m: ([], []) for m in MODELS}
        for seed in range(args.seeds):
            d, peak = measure(seed, rate_hz, args.seconds)
            pipe_ms += d["ms"].tolist()
            for m, make_filter in MODELS.items():
                rms, nees, us = run_filter(make_filter, d)
                per_model[m][0].append(rms)
                per_model[m][1].append(nees)
                cost[m] += us
            if rate_hz == 10.0:
                clean = latency(seed, False, DELAYS_S)
                real = latency(seed, True, DELAYS_S)
                for delay, fit, art in zip(DELAYS_S, clean, real, strict=True):
                    z = (fit.delay_s - delay) / fit.sigma_s
                    seen = f"{1e3 * art.delay_s:.1f} +/- {1e3 * art.sigma_s:.1f}"
                    lat_rows.append(
                        [
                            str(seed),
                            f"{1e3 * delay:.0f}",
                            f"{1e3 * fit.delay_s:.1f}",
                            f"{1e3 * fit.sigma_s:.1f}",
                            f"{z:+.2f}",
                            "yes" if abs(z) <= 3 else "NO",
                            seen,
                        ]
                    )
        for m in MODELS:
            rms, nees = np.median(per_model[m][0]), np.median(per_model[m][1])
            rate_rows.append(
                [f"{rate_hz:g} Hz", m, f"{rms:.2f}", f"{100 * rms / peak:.1f} %", f"{nees:.1f}"]
            )
    print(
        f"yaw rate on the turntable's sine (5 deg, 4 s; peak {peak:.2f} deg/s), after "
        f"5 s; medians over {args.seeds} seeds (NEES: 12 for a consistent covariance)"
    )
    print(table(["frames", "model", "rate RMS error (deg/s)", "of peak", "mean NEES"], rate_rows))
    print()
    print(
        "latency fit on 10 Hz poses stamped late by a programmed delay: frames without "
        "motion artefacts (the fit must find the delay), and with them (the sensor as "
        "simulated: their attitude bias grows with the rate and reads as latency)"
    )
    print(
        table(
            [
                "seed",
                "programmed delay (ms)",
                "fitted (ms)",
                "1-sigma (ms)",
                "error / sigma",
                "within 3 sigma",
                "with motion artefacts (ms)",
            ],
            lat_rows,
        )
    )
    print()
    tumbles = [tumble_errors(seed) for seed in range(max(args.seeds, 6))]
    print(
        f"rate on a free tumble (3-8 deg/s about a random axis, 3-8 m, 10 Hz, measured as "
        f"`estimate --filter` does: each pose from its own frame): RMS error / rate over "
        f"{len(tumbles)} seeds, after 3 s and over every frame (from the first pose)"
    )
    print(
        table(
            ["model", "after 3 s, median", "worst", "every frame, median", "worst"],
            [
                [
                    m,
                    *(
                        f"{100 * agg([e[key] for e in tumbles]):.0f} %"
                        for key in (m, f"{m}, all")
                        for agg in (np.median, max)
                    ),
                ]
                for m in (*MODELS, SMOOTHED)
            ],
        )
    )
    print()
    pm, pp = med_p95(pipe_ms)
    cost_rows = [[m, *(f"{x:.0f}" for x in med_p95(us))] for m, us in cost.items()]
    print(
        f"filter update, us per frame, one core (the pipeline on the same frames: median "
        f"{pm:.1f} ms, p95 {pp:.1f} ms)"
    )
    print(table(["model", "median us", "p95 us"], cost_rows))


if __name__ == "__main__":
    main()
