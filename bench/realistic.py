"""The pipeline on a realistic, uncalibrated ToF sensor, and after range calibration.

Three sensors see the same poses: the ideal simulated sensor (shot noise only), the
realistic one (``SystematicErrors()``: cyclic, amplitude-related, per-pixel, drift and
lens scatter; frames taken one hour after power-on), and the realistic one with the
range correction fitted from a separate calibration run (rail 0.7-8 m, the distances the
bench measures at; three attitudes, three integration times per pose, other seeds;
``tofpose.calibration.range``). Per range:
success rate, median / p95 position and attitude error against the rendered truth, the
median number of matched markers against the number in view, and "wrong" poses: reported
``ok`` but outside max(1 deg, 3 reported sigmas) or max(20 mm, 0.5 % of range, 3 sigmas).
Markers: matched by the pipeline / found by a plain detector (OpenCV SimpleBlobDetector,
a keypoint within 3 px of the marker's true image position) / in view (median).

A second part looks for confident wrong poses and checks the reported covariance over
0.7-8 m (the wrong-pose rule is stated for 3-8 m, where 4-5 markers may be matched):
random attitudes up to 20 deg (random axis) and lateral offsets up to a quarter of the
half field of view, ``--long-frames`` frames per range and sensor. Per range: how many
are refused, how many reported ``ok`` are wrong (as above), and the consistency of the
reported covariance:
the mean NEES (normalised estimation error squared over the 6 pose components, error
rotation vector and translation) against its 95 % band for that many frames, and the
share of frames inside the per-frame 95 % bound chi2_6 = 12.6.

Run: ``python bench/realistic.py [--frames N] [--long-frames N] [--cal-frames N] [--out DIR]``
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import fmt, pose_errors, pyplot, save_figure, stats, table  # noqa: E402
from bench.accuracy import random_pose  # noqa: E402
from bench.baseline import blob_detector  # noqa: E402
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target  # noqa: E402
from tofpose.calibration.covariance import fit_covariance_scale, pose_nees  # noqa: E402
from tofpose.calibration.range import fit_range_correction  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.calibration_run import calibration_frames  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import FIRST_DISC, TargetScene  # noqa: E402
from tofpose.sim.systematic import SystematicErrors  # noqa: E402

RANGES_M = [0.7, 1.0, 1.5, 2.0, 3.0, 4.5, 6.0, 8.0]
WARM_S = 3600.0  # frames are taken (and the calibration run) an hour after power-on
SENSORS = ("ideal", "realistic", "realistic, calibrated")


def calibration_samples(cam: CameraModel, errors: SystematicErrors, seed: int = 99):
    """A calibration run: frames of the known target at known poses (module docstring)."""
    poses = [
        RigidTransform(rotation_from_euler_deg(p, y, 0.0) @ R_FACING, np.array([ox, oy, z]))
        for z in np.linspace(700.0, 8000.0, 25)
        for p, y, ox, oy in ((0, 0, 0, 0), (4, -5, 150, -80), (-3, 6, -200, 60))
    ]
    return calibration_frames(
        cam, paper_target(), errors, poses, np.random.default_rng(seed), time_s=WARM_S
    )


def _simple_detected(f, T, cam, cat, detector) -> int:
    """Markers a plain detector finds: OpenCV's SimpleBlobDetector on the gray image
    (bench/baseline.py) with a keypoint within 3 px of the marker's true image position."""
    img8 = np.clip(f.gray / 16.0, 0, 255).astype(np.uint8)
    pts = np.array([k.pt for k in detector.detect(img8)]).reshape(-1, 2)
    p = cat.positions_mm @ T.R.T + T.t_mm
    front = p[:, 2] > 0
    if not len(pts) or not front.any():
        return 0
    proj = cam.project(p[front])
    d = np.linalg.norm(proj[:, None, :] - pts[None, :, :], axis=2)
    return int(np.count_nonzero(d.min(axis=1) < 3.0))


def _in_view(f) -> int:
    """Markers with at least one pixel centre in the image."""
    ids = f.surface_id[f.surface_id >= FIRST_DISC]
    return int(np.count_nonzero(np.bincount(ids) >= 1))


def _wrong(res, T, range_m: float) -> bool:
    pe, ae = pose_errors(res.R, res.t_mm, T)
    sd = np.sqrt(np.clip(np.diag(res.covariance), 0, None)) if res.covariance is not None else None
    s_att = np.degrees(np.linalg.norm(sd[:3])) if sd is not None else 0.0
    s_pos = float(np.linalg.norm(sd[3:])) if sd is not None else 0.0
    return ae > max(1.0, 3 * s_att) or pe > max(20.0, 0.005 * range_m * 1000.0, 3 * s_pos)


def _pipeline(cam, cat, corr, covariance_scale=None) -> PosePipeline:
    """The ideal sensor is known to have no range bias (``"ideal"``); the others get the
    default prior for an uncalibrated or a calibrated camera."""
    if isinstance(corr, str):
        return PosePipeline(
            cam, cat, PipelineConfig(range_bias_sigma_mm=0.0), covariance_scale=covariance_scale
        )
    return PosePipeline(cam, cat, range_correction=corr, covariance_scale=covariance_scale)


def run(n_frames: int = 12, seed: int = 0, long_frames: int = 90, cal_frames: int = 60):
    cam, cat = CameraModel(), paper_target()
    errors = SystematicErrors()
    fit = fit_range_correction(calibration_samples(cam, errors), SensorModel().unambiguous_range_mm)
    sensors = {
        "ideal": (SensorModel(), "ideal"),
        "realistic": (SensorModel(systematic=errors), None),
        "realistic, calibrated": (SensorModel(systematic=errors), fit.correction),
    }
    rows = []  # (sensor, range, ok, pos_err, att_err, n_matched, n_in_view, wrong, n_simple)
    long_rows = run_long_range(fit, long_frames, cal_frames=cal_frames)
    detector = blob_detector()
    for r in tqdm(RANGES_M, desc="realistic sensor", unit="range", file=sys.stderr):
        rng = np.random.default_rng([seed, int(r * 1000)])
        poses = [random_pose(r, rng) for _ in range(n_frames)]
        for name, (sensor, corr) in sensors.items():
            pipe = _pipeline(cam, cat, corr)
            frng = np.random.default_rng([seed, int(r * 1000), 7])  # same noise per sensor
            for T in poses:
                f = render_frame(cam, TargetScene(cat), T, sensor, frng, time_s=WARM_S)
                pipe.reset()
                res = pipe.process(f.gray, f.distance_mm)
                simple = _simple_detected(f, T, cam, cat, detector)
                if res.ok:
                    pe, ae = pose_errors(res.R, res.t_mm, T)
                    rows.append(
                        (
                            name,
                            r,
                            True,
                            pe,
                            ae,
                            res.n_matched,
                            _in_view(f),
                            _wrong(res, T, r),
                            simple,
                        )
                    )
                else:
                    rows.append((name, r, False, np.nan, np.nan, 0, _in_view(f), False, simple))
    return {
        "rows": rows,
        "fit": fit,
        "long": long_rows,
        "long_frames": long_frames,
        "cal_frames": cal_frames,
    }


#: the rule for wrong poses is stated for 3-8 m (4-5 markers at long range); the nearer
#: ranges show the covariance's consistency over the whole operating range
CONSISTENCY_RANGES_M = [0.7, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
NEES_95_PER_FRAME = 12.592  # chi2_6, 95 %


def long_range_pose(range_m: float, rng: np.random.Generator) -> RigidTransform:
    """Attitude up to 20 deg about a random axis, lateral offset up to a quarter of the
    half field of view (module docstring)."""
    from scipy.spatial.transform import Rotation

    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    R = Rotation.from_rotvec(axis * np.radians(rng.uniform(0.0, 20.0))).as_matrix() @ R_FACING
    z = range_m * 1000.0
    t = np.array([rng.uniform(-1, 1) * 0.25 * 0.49 * z, rng.uniform(-1, 1) * 0.25 * 0.37 * z, z])
    return RigidTransform(R, t)


def nees(res, T) -> float:
    """e^T Sigma^-1 e over (rotation vector error, translation error), the covariance's
    own parameterisation (left perturbation)."""
    return pose_nees(res.R, res.t_mm, res.covariance, T.R, T.t_mm)


def _consistency_frames(sensor, pipe, r: float, n: int, seed: int):
    """(truth, result) of ``n`` long-range poses at ``r`` m, each frame on its own."""
    cam, cat = pipe.camera, pipe.catalog
    rng = np.random.default_rng([seed, int(r * 1000)])
    poses = [long_range_pose(r, rng) for _ in range(n)]
    frng = np.random.default_rng([seed, int(r * 1000), 7])
    for T in poses:
        f = render_frame(cam, TargetScene(cat), T, sensor, frng, time_s=WARM_S)
        pipe.reset()
        yield T, pipe.process(f.gray, f.distance_mm)


def covariance_calibration(sensor, corr, n_frames: int, seed: int = 2):
    """The sensor's covariance factors, fitted on frames of its own (other poses and
    noise than the consistency run's), knots at the consistency ranges."""
    cam, cat = CameraModel(), paper_target()
    pipe = _pipeline(cam, cat, corr)
    ranges, values = [], []
    for r in CONSISTENCY_RANGES_M:
        for T, res in _consistency_frames(sensor, pipe, r, n_frames, seed):
            if res.ok:
                ranges.append(float(np.linalg.norm(T.t_mm)))
                values.append(nees(res, T))
    return fit_covariance_scale(ranges, values, [r * 1000.0 for r in CONSISTENCY_RANGES_M])


def run_long_range(fit, n_frames: int, seed: int = 1, cal_frames: int = 60) -> list:
    """Rows (sensor, range, ok, wrong, NEES, matched, NEES calibrated, wrong calibrated):
    wrong and NEES with the model's covariance, then with the covariance calibrated on
    ``cal_frames`` other frames per range (``covariance_calibration``); the poses are
    the same."""
    cam, cat = CameraModel(), paper_target()
    errors = SystematicErrors()
    sensors = {
        "ideal": (SensorModel(), "ideal"),
        "realistic": (SensorModel(systematic=errors), None),
        "realistic, calibrated": (SensorModel(systematic=errors), fit.correction),
    }
    rows = []
    for name, (sensor, corr) in tqdm(
        sensors.items(), desc="consistency", unit="sensor", file=sys.stderr
    ):
        scale = covariance_calibration(sensor, corr, cal_frames).scale
        pipe = _pipeline(cam, cat, corr, scale)
        for r in CONSISTENCY_RANGES_M:
            for T, res in _consistency_frames(sensor, pipe, r, n_frames, seed):
                if not res.ok:
                    rows.append((name, r, False, False, np.nan, 0, np.nan, False))
                    continue
                factor = scale.factor_at(float(np.linalg.norm(res.t_mm)))
                model = replace(res, covariance=res.covariance / factor)
                rows.append(
                    (
                        name,
                        r,
                        True,
                        _wrong(model, T, r),
                        nees(model, T),
                        res.n_matched,
                        nees(res, T),
                        _wrong(res, T, r),
                    )
                )
    return rows


def consistency(ns: np.ndarray) -> tuple[float, float, float, str]:
    """Mean NEES of k frames, its 95 % band (chi2 with 6k dof, / k) and the verdict."""
    from scipy.stats import chi2

    k = len(ns)
    if not k:
        return np.nan, np.nan, np.nan, "-"
    lo, hi = chi2.ppf([0.025, 0.975], 6 * k) / k
    mean = float(np.mean(ns))
    return (
        mean,
        lo,
        hi,
        ("in band" if lo <= mean <= hi else "too wide" if mean < lo else "too narrow"),
    )


def _share(ns: np.ndarray) -> str:
    """Share of frames inside the per-frame 95 % bound."""
    return f"{np.mean(ns <= NEES_95_PER_FRAME):.0%}" if len(ns) else "-"


def long_range_table(rows) -> str:
    out = []
    for r in CONSISTENCY_RANGES_M:
        for name in SENSORS:
            sel = [x for x in rows if x[0] == name and x[1] == r]
            ok = [x for x in sel if x[2]]
            ns, nc = np.array([x[4] for x in ok]), np.array([x[6] for x in ok])
            mean, lo, hi, verdict = consistency(ns)
            mean_c, _, _, verdict_c = consistency(nc)
            out.append(
                [
                    f"{r:g}",
                    name,
                    str(len(sel)),
                    str(len(sel) - len(ok)),
                    f"{sum(x[3] for x in ok)} / {sum(x[7] for x in ok)}",
                    f"{np.median([x[5] for x in ok]):.0f}" if ok else "-",
                    f"{lo:.1f}-{hi:.1f}",
                    f"{mean:.1f}",
                    verdict,
                    f"{np.sqrt(mean / 6):.2f}",
                    _share(ns),
                    f"{mean_c:.1f}",
                    verdict_c,
                    _share(nc),
                ]
            )
    return table(
        [
            "range m",
            "sensor",
            "frames",
            "refused",
            "wrong ok poses (model / cal.)",
            "matched (median)",
            "95 % band",
            "mean NEES, model",
            "model covariance",
            "errors / reported sigmas, model",
            "NEES <= 12.6, model",
            "mean NEES, calibrated",
            "calibrated covariance",
            "NEES <= 12.6, calibrated",
        ],
        out,
    )


def summarise(data) -> dict:
    out = {}
    for name in SENSORS:
        for r in RANGES_M:
            sel = [x for x in data["rows"] if x[0] == name and x[1] == r]
            out[(name, r)] = {
                "ok": float(np.mean([x[2] for x in sel])),
                "pos": stats([x[3] for x in sel]),
                "att": stats([x[4] for x in sel]),
                "matched": float(np.median([x[5] for x in sel])),
                "in_view": float(np.median([x[6] for x in sel])),
                "simple": float(np.median([x[8] for x in sel])),
                "wrong": int(sum(x[7] for x in sel)),
                "n": len(sel),
            }
    return out


def plot(data, path: Path) -> None:
    plt = pyplot()
    s = summarise(data)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, style in zip(SENSORS, ("k-", "o--", "s-"), strict=True):
        axes[0].semilogy(
            RANGES_M, [s[(name, r)]["pos"]["median"] for r in RANGES_M], style, label=name, ms=4
        )
        axes[1].semilogy(
            RANGES_M, [s[(name, r)]["att"]["median"] for r in RANGES_M], style, label=name, ms=4
        )
    axes[0].set_ylabel("median position error (mm)")
    axes[1].set_ylabel("median attitude error (deg)")
    for ax in axes:
        ax.set_xlabel("range (m)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    save_figure(fig, path)


def markdown(data, img: str, n_frames: int) -> str:
    s = summarise(data)
    fit = data["fit"]
    rows = []
    for r in RANGES_M:
        for name in SENSORS:
            x = s[(name, r)]
            rows.append(
                [
                    f"{r:g}",
                    name,
                    f"{x['ok']:.0%}",
                    fmt(x["pos"]["median"]),
                    fmt(x["pos"]["p95"]),
                    fmt(x["att"]["median"], 3),
                    fmt(x["att"]["p95"], 3),
                    f"{x['matched']:.0f} / {x['simple']:.0f} / {x['in_view']:.0f}",
                    f"{x['wrong']} / {x['n']}",
                ]
            )
    c = fit.correction
    harm = ", ".join(f"{np.hypot(a, b):.1f}" for a, b in c.harmonics_mm)
    return "\n".join(
        [
            "## Realistic sensor and range calibration",
            "",
            f"`bench/realistic.py`, {n_frames} random poses (+-5 deg) per range, the same poses "
            "for the three sensors. Calibration run: "
            f"{fit.n_frames} frames, {fit.n_samples} pixel samples; fitted cyclic amplitudes "
            f"{harm} mm (programmed {', '.join(f'{a:g}' for a in SystematicErrors().wiggle_amplitudes_mm)}), "  # noqa: E501
            f"amplitude term {c.amplitude_mm_per_decade:.1f} mm/decade (programmed "
            f"{SystematicErrors().amplitude_mm_per_decade:g}), "
            f"{fit.pixels_with_offset} pixels with "
            f"an offset; residual RMS {fit.rms_before_mm:.1f} -> {fit.rms_after_mm:.1f} mm "
            f"(noise included); calibrated span {c.calibrated_span_mm[0]:.0f}-"
            f"{c.calibrated_span_mm[1]:.0f} mm (measured distances of the samples used).",
            "",
            table(
                [
                    "range m",
                    "sensor",
                    "ok",
                    "pos median mm",
                    "pos p95 mm",
                    "att median deg",
                    "att p95 deg",
                    "matched / simple detector / in view",
                    "wrong ok poses",
                ],
                rows,
            ),
            "",
            f"![realistic sensor]({img})",
            "",
            "### Wrong poses and covariance consistency, 0.7-8 m",
            "",
            f"{data['long_frames']} frames per range and sensor, attitudes up to 20 deg, lateral "
            "offsets (module docstring). A wrong pose is one reported `ok` outside max(1 deg, "
            "3 reported sigmas) or max(20 mm, 0.5 % of range, 3 sigmas), counted with the "
            'model\'s covariance and with the calibrated one; "covariance" says '
            "whether the mean NEES lies in its 95 % band (too narrow: the reported sigmas "
            'claim more than the errors show); "errors / reported sigmas" is sqrt(mean NEES '
            "/ 6), the factor by which the errors' spread differs from the reported one (1: "
            "consistent, below 1: the reported sigmas are wider than the errors). Model: the "
            "covariance of the measurement model (`tofpose.stages.extraction.uncertainty`, "
            "floors included). "
            f"Calibrated: the same poses, the covariance times the sensor's factor per range "
            f"(`tofpose.calibration.covariance`) fitted on {data['cal_frames']} other frames per "
            "range of the same sensor (other poses and noise), as `tofpose calibrate-covariance` "
            "fits it from a recording with a reference pose.",
            "",
            long_range_table(data["long"]),
            "",
        ]
    )


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--long-frames", type=int, default=90)
    ap.add_argument("--cal-frames", type=int, default=150)
    ap.add_argument("--out", default="docs/img/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = run(args.frames, long_frames=args.long_frames, cal_frames=args.cal_frames)
    plot(data, out / "realistic.png")
    print(markdown(data, str(out / "realistic.png"), args.frames))


if __name__ == "__main__":
    main()
