"""Pixel-level pose fit against the centroid pipeline and the Cramer-Rao bound (issue 49,
item 1).

Per range, frames are rendered with truth (``SensorModel(supersampling=16)``, noise on;
poses drawn around a facing target: +-5 deg per axis, +-150 mm across the view), the
pipeline measures them, and ``fit_pose_to_pixels`` refines its pose on the matched
markers' pixels. Reported per range, medians over repeats of ``--frames`` frames each:
RMS attitude (deg, geodesic) and position (mm) errors of the pipeline and of the pixel
fit, their ratios to the bound (``bench/crlb.py``, RMS over the same frames), the pixel
fit's errors over its own sigmas (RMS of the whitened 3-D errors over sqrt(3)), its
fallback count and its time per frame (one BLAS thread, as the CLI runs: with
OpenBLAS's two threads on a busy 2-core machine the fit's products of a (rows, ~70)
Jacobian dominated, and a profile of 9 fits at 1-8 m took 2.9 s against 0.38 s with
one). ``--jacobian central-differences`` fits with the pose's Jacobian by central
differences (twelve model calls an iteration) instead of the analytic derivatives: the
same frames, to compare.

    python bench/pixelfit.py --ranges 1 2 3 4 5 6 7 8 --frames 20 --repeats 3

``--product`` adds the fit as the product runs it (``PosePipeline`` with the pixel fit
on, as ``tofpose estimate``), per sensor and camera configuration (``PRODUCT_SENSORS``):
the ideal sensor with the camera declared bias-free, the ideal sensor with the defaults
(a common range offset fitted under the uncalibrated prior), and the realistic sensor
(``SystematicErrors()``, an hour after power-on) with its range calibration
(``bench/realistic.py``'s calibration run) and the calibrated prior; the bound is the
offset-known one throughout, so a fitted offset shows as position over the bound.

Judge the pixel fit on frames rendered with ``--supersampling 64`` (32 at 3 m and beyond): the
renderer's 16 x 16 point sampling of an edge pixel leaves +-10-40 counts on each rim
pixel (one sample is 1/256 of a ~2500-count disc), which for a fit on the rim pixels is a
model error of 0.5-2 bounds (at 3 m: 1.36 / 1.41 bounds and errors/sigmas 1.35 at 16,
1.06 / 1.16 and 0.87 / 1.12 at 32). At 2 m 32 is still coarse: 12 frames x 2 repeats
gave attitude 1.25 bounds and errors/sigmas 1.11 at 32, 0.98 and 0.99 at 64 (the fit's
own 8 x 8 sub-cells in place of 4 x 4 changed neither: 0.98, 0.99), so the report renders
at 64. On noiseless frames at 64 x 64 the fit's own model error is 0.1-0.45 bounds (1-3
m; the quadratic gain over large discs and the 4 x 4 sub-cells with straight rims are
what it leaves).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.crlb import pose_crlb  # noqa: E402
from tofpose import CameraModel, PosePipeline, paper_target  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.core.threads import single_threaded_blas  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import TargetScene  # noqa: E402
from tofpose.stages.pixelfit.fit import PixelNoise, fit_pose_to_pixels  # noqa: E402


@dataclass(frozen=True)
class FrameOutcome:
    """One frame: errors (rotation vector rad, translation mm) of the pipeline and of the
    pixel fit (None when it fell back or the pipeline failed), the pixel fit's
    covariance, the bound (position mm, attitude deg) and the fit's time, s."""

    pipeline_err: np.ndarray | None
    pixel_err: np.ndarray | None
    covariance: np.ndarray | None
    bound: tuple[float, float]
    fit_s: float
    reason: str


def draw_pose(rng: np.random.Generator, range_mm: float) -> RigidTransform:
    """A target facing the camera within +-5 deg per axis, +-150 mm across the view."""
    e = rng.uniform(-5.0, 5.0, 3)
    t = np.array([*rng.uniform(-150.0, 150.0, 2), range_mm])
    return RigidTransform(rotation_from_euler_deg(*e) @ R_FACING, t)


def pose_error(R: np.ndarray, t_mm: np.ndarray, T: RigidTransform) -> np.ndarray:
    """(6,) rotation vector of ``R T.R^T`` (rad, left-multiplied) and ``t - T.t``, mm."""
    return np.concatenate([Rotation.from_matrix(R @ T.R.T).as_rotvec(), t_mm - T.t_mm])


def run_frame(
    rng: np.random.Generator,
    range_mm: float,
    *,
    sensor: SensorModel,
    camera: CameraModel | None = None,
    jacobian: str = "analytic",
) -> FrameOutcome:
    """Render one frame at ``range_mm``, run the pipeline and the pixel fit (its
    ``jacobian`` option) on it."""
    cam = CameraModel() if camera is None else camera
    cat = paper_target()
    T = draw_pose(rng, range_mm)
    f = render_frame(cam, TargetScene(), T, sensor, rng)
    bound = pose_crlb(f, T, cam, cat, sensor)
    r = PosePipeline(cam, cat).process(f.gray, f.distance_mm)
    if not r.ok:
        return FrameOutcome(None, None, None, bound, 0.0, f"pipeline: {r.reason}")
    t0 = time.perf_counter()
    fit = fit_pose_to_pixels(
        f.gray,
        f.distance_mm,
        cam,
        cat,
        r.R,
        r.t_mm,
        [m.catalog_id for m in r.matched],
        noise=PixelNoise.from_sensor(sensor),
        jacobian=jacobian,
    )
    dt = time.perf_counter() - t0
    pixel_err = pose_error(fit.R, fit.t_mm, T) if fit.ok else None
    return FrameOutcome(
        pose_error(r.R, r.t_mm, T), pixel_err, fit.covariance, bound, dt, fit.reason
    )


def summarise(outcomes: list[FrameOutcome]) -> dict[str, float]:
    """RMS errors, bound (RMS over the frames), errors over sigmas, fallbacks, ms."""

    def rms(errs, sl):
        return float(np.sqrt(np.mean([np.sum(e[sl] ** 2) for e in errs])))

    pipe = [o.pipeline_err for o in outcomes if o.pipeline_err is not None]
    pix = [o for o in outcomes if o.pixel_err is not None]
    bound_pos = float(np.sqrt(np.nanmean([o.bound[0] ** 2 for o in outcomes])))
    bound_att = float(np.sqrt(np.nanmean([o.bound[1] ** 2 for o in outcomes])))
    z_att, z_pos = [], []
    for o in pix:
        e, C = o.pixel_err, o.covariance
        z_att.append(e[:3] @ np.linalg.solve(C[:3, :3], e[:3]) / 3)
        z_pos.append(e[3:] @ np.linalg.solve(C[3:, 3:], e[3:]) / 3)
    return {
        "pipe_att_deg": float(np.degrees(rms(pipe, slice(0, 3)))) if pipe else np.nan,
        "pipe_pos_mm": rms(pipe, slice(3, 6)) if pipe else np.nan,
        "pix_att_deg": float(np.degrees(rms([o.pixel_err for o in pix], slice(0, 3))))
        if pix
        else np.nan,
        "pix_pos_mm": rms([o.pixel_err for o in pix], slice(3, 6)) if pix else np.nan,
        "bound_att_deg": bound_att,
        "bound_pos_mm": bound_pos,
        "z_att": float(np.sqrt(np.mean(z_att))) if pix else np.nan,
        "z_pos": float(np.sqrt(np.mean(z_pos))) if pix else np.nan,
        "fallbacks": float(sum(o.pixel_err is None for o in outcomes)),
        "ms": 1e3 * float(np.median([o.fit_s for o in outcomes if o.fit_s > 0])) if pix else np.nan,
    }


#: the product table's sensors and camera configurations (``_product_pipelines``)
PRODUCT_SENSORS = (
    "ideal, declared bias-free",
    "ideal, defaults (uncalibrated prior)",
    "realistic, calibrated",
)
#: realistic frames are taken an hour after power-on, as ``bench/realistic.py`` takes them
WARM_S = 3600.0


def _product_pipelines(
    cam: CameraModel, supersampling: int = 32, names: tuple[str, ...] = PRODUCT_SENSORS
) -> dict[str, tuple[SensorModel, PosePipeline]]:
    """Per entry of ``names`` (of ``PRODUCT_SENSORS``): the renderer's sensor
    (``supersampling`` squared points per rim pixel) and the pipeline as a user
    configures it for that camera (pixel fit on): the ideal sensor declared bias-free
    (``range_bias_sigma_mm=0``), the ideal sensor with the defaults, the realistic one
    with the range correction of ``bench/realistic.py``'s calibration run."""
    from tofpose import PipelineConfig
    from tofpose.config import PixelFitConfig

    cat = paper_target()
    fit_on = PixelFitConfig(enabled=True)
    defaults = PipelineConfig(pixel_fit=fit_on)
    out: dict[str, tuple[SensorModel, PosePipeline]] = {}
    if PRODUCT_SENSORS[0] in names:
        bias_free = PipelineConfig(range_bias_sigma_mm=0.0, pixel_fit=fit_on)
        out[PRODUCT_SENSORS[0]] = (
            SensorModel(supersampling=supersampling),
            PosePipeline(cam, cat, bias_free),
        )
    if PRODUCT_SENSORS[1] in names:
        out[PRODUCT_SENSORS[1]] = (
            SensorModel(supersampling=supersampling),
            PosePipeline(cam, cat, defaults),
        )
    if PRODUCT_SENSORS[2] in names:
        from bench.realistic import calibration_samples
        from tofpose.calibration.range import fit_range_correction
        from tofpose.sim.systematic import SystematicErrors

        errors = SystematicErrors()
        correction = fit_range_correction(
            calibration_samples(cam, errors), SensorModel().unambiguous_range_mm
        ).correction
        out[PRODUCT_SENSORS[2]] = (
            SensorModel(supersampling=supersampling, systematic=errors),
            PosePipeline(cam, cat, defaults, range_correction=correction),
        )
    return out


def product_frame(
    rng: np.random.Generator, range_mm: float, sensor: SensorModel, pipe: PosePipeline
) -> tuple[FrameOutcome, float]:
    """One frame through the product's pipeline (pixel fit on, as ``tofpose estimate``
    runs it): its pose when the fit held (else a fallback), against the offset-known
    bound; and the range-offset prior sigma the pose was fitted with (mm; 0: none, NaN:
    no pose)."""
    cam, cat = pipe.camera, pipe.catalog
    T = draw_pose(rng, range_mm)
    time_s = WARM_S if sensor.systematic is not None else 0.0
    f = render_frame(cam, TargetScene(), T, sensor, rng, time_s=time_s)
    bound = pose_crlb(f, T, cam, cat, sensor)
    pipe.reset()
    r = pipe.process(f.gray, f.distance_mm)
    prior_mm = r.range_offset.prior_sigma_mm if r.ok else np.nan
    if not r.ok or r.pixel_fit != "ok" or r.R is None or r.t_mm is None:
        return FrameOutcome(None, None, None, bound, 0.0, r.reason or str(r.pixel_fit)), prior_mm
    err = pose_error(r.R, r.t_mm, T)
    fit_s = 1e-3 * r.timings_ms["pixel fit"]
    return FrameOutcome(err, err, r.covariance, bound, fit_s, ""), prior_mm


def product_table(
    ranges: list[float], frames: int, repeats: int, seed: int, supersampling: int
) -> str:
    """The pixel fit as the product runs it (``PosePipeline`` with ``pixel_fit`` on, the
    camera configured as a user would: ``PRODUCT_SENSORS``), RMS errors over the bound with
    the range offset known (the sensor's physics alone), errors over the reported sigmas,
    the frames where the fit fell back (the centroid pose reported instead), and the
    range-offset prior the poses were fitted with (a calibrated camera's holds only where
    every reflector lies in the calibration's span: beyond, the uncalibrated one)."""
    pipes = _product_pipelines(CameraModel(), supersampling)
    lines = [
        "| range m | sensor, camera configured as | offset prior mm (median used) "
        "| att / bound | pos / bound | err/sigma att | err/sigma pos | fallbacks |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for z in ranges:
        for name, (sensor, pipe) in pipes.items():
            rows, priors = [], []
            for rep in range(repeats):
                rng = np.random.default_rng([seed, int(z * 1000), rep])
                done = [product_frame(rng, z * 1000.0, sensor, pipe) for _ in range(frames)]
                rows.append(summarise([o for o, _ in done]))
                priors += [p for _, p in done]
            m = {k: float(np.nanmedian([r[k] for r in rows])) for k in rows[0]}
            lines.append(
                f"| {z:g} | {name} | {np.nanmedian(priors):g} "
                f"| {m['pix_att_deg'] / m['bound_att_deg']:.2f} "
                f"| {m['pix_pos_mm'] / m['bound_pos_mm']:.2f} | {m['z_att']:.2f} "
                f"| {m['z_pos']:.2f} | {m['fallbacks']:.0f} |"
            )
            print(lines[-1], file=sys.stderr, flush=True)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranges", type=float, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--supersampling", type=int, default=16)
    ap.add_argument("--seed", type=int, default=49)
    ap.add_argument("--jacobian", choices=("analytic", "central-differences"), default="analytic")
    ap.add_argument(
        "--product",
        action="store_true",
        help="also the fit as the product runs it, per sensor and camera configuration",
    )
    args = ap.parse_args(argv)
    single_threaded_blas()
    sensor = SensorModel(supersampling=args.supersampling)
    lines = [
        f"Pixel fit vs centroid pipeline vs bound: {args.frames} frames x {args.repeats} "
        f"repeats per range (medians over repeats), renderer supersampling "
        f"{args.supersampling}, {args.jacobian} pose Jacobian.",
        "",
        "| range m | pipeline att / bound | pixel att / bound | pipeline pos / bound "
        "| pixel pos / bound | bound att mdeg | bound pos mm | err/sigma att | err/sigma pos "
        "| fallbacks | ms / frame |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for z in args.ranges:
        rows = []
        for rep in range(args.repeats):
            rng = np.random.default_rng([args.seed, int(z * 1000), rep])
            out = [
                run_frame(rng, z * 1000.0, sensor=sensor, jacobian=args.jacobian)
                for _ in range(args.frames)
            ]
            rows.append(summarise(out))
        m = {k: float(np.nanmedian([r[k] for r in rows])) for k in rows[0]}
        lines.append(
            f"| {z:g} | {m['pipe_att_deg'] / m['bound_att_deg']:.2f} "
            f"| {m['pix_att_deg'] / m['bound_att_deg']:.2f} "
            f"| {m['pipe_pos_mm'] / m['bound_pos_mm']:.2f} "
            f"| {m['pix_pos_mm'] / m['bound_pos_mm']:.2f} "
            f"| {1e3 * m['bound_att_deg']:.2f} | {m['bound_pos_mm']:.3f} "
            f"| {m['z_att']:.2f} | {m['z_pos']:.2f} | {m['fallbacks']:.0f} | {m['ms']:.0f} |"
        )
        print(lines[-1], file=sys.stderr, flush=True)  # progress; the table goes to stdout
    if args.product:
        lines += [
            "",
            f"The fit as the product runs it (`PosePipeline` with the pixel fit on, as "
            f"`tofpose estimate`), per sensor and camera configuration: {args.frames} frames x "
            f"{args.repeats} repeats per range, the same poses for each; bound with the range "
            "offset known; fallbacks: frames reported with the centroid pose.",
            "",
            product_table(args.ranges, args.frames, args.repeats, args.seed, args.supersampling),
        ]
    text = "\n".join(lines)
    print(text)
    return text


if __name__ == "__main__":
    main()
