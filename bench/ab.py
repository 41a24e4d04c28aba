"""A/B harness for pipeline changes that must not change the answer: the same fixed
frames (the speed bench's ranges as a stream, plus independent random poses from 0.5 to
12 m, with and without spurious blobs) through the pipeline, with tracking off and on;
``--save`` stores every frame's ok flag, matched ids, R, t, reported covariance and
mode; ``--compare`` reports the largest differences against a saved run and fails when
any exceeds 1e-6 mm / 1e-6 deg / 1e-6 of the covariance's largest entry, or a flag or
mode differs (a saved run without covariances is compared without them).

Run: ``python bench/ab.py --save before.npz`` (old code), then
``python bench/ab.py --compare before.npz`` (new code).

``--implementation reference`` runs the frames through ``PosePipeline(...,
implementation="reference")`` (every stage's arithmetic by ``tofpose.reference``; slow)
instead of the kernels; compared against a saved compiled run it needs stated
tolerances, ``--tolerance-mm``, ``--tolerance-deg`` and ``--tolerance-cov`` (the
reference's ML fit is SciPy's ``least_squares``, equal to the kernels' only to its
tolerance).

``--pixel-fit`` runs both pipelines with the pixel-level fit on
(``PipelineConfig.pixel_fit``): each ok pose refined on its pixels, and the fit's outcome
(``PoseResult.pixel_fit``) compared as the modes are. Its saved runs compare only with
runs of the same flag.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.accuracy import random_pose  # noqa: E402
from bench.pipeline import CASES  # noqa: E402
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target  # noqa: E402
from tofpose.config import PixelFitConfig, TrackingConfig  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import Clutter, TargetScene  # noqa: E402

TOL = 1e-6


def frames():
    """(stream id, gray, distance) in a fixed order: each stream goes through one pipeline
    without reset (persistence active), as in the speed bench."""
    cam = CameraModel()
    rng = np.random.default_rng(0)
    for k, (z, off) in enumerate(CASES):
        T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([*off, z]))
        for _ in range(20):
            f = render_frame(cam, TargetScene(), T, SensorModel(), rng)
            yield f"stream-{k}", f.gray, f.distance_mm
    rng = np.random.default_rng(1)
    for r in (0.5, 0.7, 1.0, 2.0, 3.0, 5.0, 8.0, 10.0, 12.0):
        for j in range(8):
            T = random_pose(r, rng)
            clutter = tuple(
                Clutter(
                    (rng.uniform(-600, 600), rng.uniform(-400, 400), rng.uniform(0, 200)),
                    float(rng.uniform(30, 90)),
                    1.0,
                )
                for _ in range(j % 4)
            )
            f = render_frame(
                cam, TargetScene(paper_target(), clutter=clutter), T, SensorModel(), rng
            )
            yield f"single-{r}-{j}", f.gray, f.distance_mm


def run(
    config: PipelineConfig | None = None, implementation: str = "compiled"
) -> dict[str, np.ndarray]:
    cam, cat = CameraModel(), paper_target()
    pipes: dict[str, PosePipeline] = {}
    ok, ids, Rs, ts, covs, modes, fits = [], [], [], [], [], [], []
    for stream, gray, dist in tqdm(list(frames()), desc="A/B frames", file=sys.stderr):
        key = stream if stream.startswith("stream") else "single"
        if key not in pipes:
            pipes[key] = PosePipeline(cam, cat, config, implementation=implementation)
        pipe = pipes[key]
        if key == "single":
            pipe.reset()
        r = pipe.process(gray, dist)
        ok.append(r.ok)
        ids.append(",".join(str(m.catalog_id) for m in r.matched) if r.ok else "")
        Rs.append(r.R if r.ok else np.full((3, 3), np.nan))
        ts.append(r.t_mm if r.ok else np.full(3, np.nan))
        covs.append(r.covariance if r.ok and r.covariance is not None else np.full((6, 6), np.nan))
        modes.append(r.mode)
        fits.append(r.pixel_fit)
    return {
        "ok": np.array(ok),
        "ids": np.array(ids),
        "R": np.array(Rs),
        "t": np.array(ts),
        "cov": np.array(covs),
        "mode": np.array(modes),
        "pixel_fit": np.array(fits),
    }


def run_both(implementation: str = "compiled", pixel_fit: bool = False) -> dict[str, np.ndarray]:
    """The frames through the default pipeline and through one with tracking on (its
    keys prefixed ``tracking_``); ``pixel_fit``: both with the pixel-level fit on."""
    fit = PixelFitConfig(enabled=pixel_fit)
    out = run(PipelineConfig(pixel_fit=fit), implementation=implementation)
    tracked = run(
        PipelineConfig(tracking=TrackingConfig(enabled=True), pixel_fit=fit), implementation
    )
    out.update({f"tracking_{k}": v for k, v in tracked.items()})
    return out


def compare(
    a: dict,
    b: dict,
    label: str = "acquisition",
    tol_mm: float = TOL,
    tol_deg: float = TOL,
    ids_as_sets: bool = False,
    tol_cov: float = TOL,
) -> int:
    """Print and return (1: beyond the tolerances) the differences of run ``b`` from
    ``a``; ``ids_as_sets``: matched ids compared regardless of order (the reference's
    split of a merged pair may list its halves the other way round)."""
    for key in ("mode", "pixel_fit"):
        if key in a and key in b and np.any(a[key] != b[key]):
            print(f"{label}: {key} differs on {int(np.sum(a[key] != b[key]))} frames")
            return 1
    flags = np.flatnonzero(a["ok"] != b["ok"])
    if ids_as_sets:
        idd = np.flatnonzero(
            [
                sorted(x.split(",")) != sorted(y.split(","))
                for x, y in zip(a["ids"], b["ids"], strict=True)
            ]
        )
    else:
        idd = np.flatnonzero(a["ids"] != b["ids"])
    both = a["ok"] & b["ok"]
    dt = np.linalg.norm(a["t"][both] - b["t"][both], axis=1)
    # small-angle difference from the Frobenius norm (arccos near 1 loses ~1e-6 deg)
    dR = np.degrees(np.linalg.norm(a["R"][both] - b["R"][both], axis=(1, 2)) / np.sqrt(2.0))
    # each frame's covariance difference relative to its largest entry (NaN-free frames)
    dC = np.zeros(0)
    if "cov" in a and "cov" in b:
        Ca, Cb = a["cov"][both], b["cov"][both]
        scale = np.nanmax(np.abs(Ca), axis=(1, 2), initial=0.0)
        dC = np.nanmax(np.abs(Ca - Cb), axis=(1, 2), initial=0.0) / np.maximum(scale, 1e-300)
    cov_text = f", max dcov {dC.max(initial=0):.3g} (relative)" if "cov" in a else ""
    print(
        f"{label}: frames {len(a['ok'])}, ok {int(a['ok'].sum())} / {int(b['ok'].sum())}; "
        f"ok flags differ {len(flags)}, matched ids differ {len(idd)}; "
        f"max |dt| {dt.max(initial=0):.3g} mm, max dR {dR.max(initial=0):.3g} deg{cov_text}"
    )
    for i in np.argsort(-dt)[:5] if len(dt) and dt.max() > tol_mm else []:
        print(f"  frame {np.flatnonzero(both)[i]}: |dt| {dt[i]:.3g} mm, dR {dR[i]:.3g} deg")
    return int(
        len(flags) > 0
        or len(idd) > 0
        or dt.max(initial=0) > tol_mm
        or dR.max(initial=0) > tol_deg
        or dC.max(initial=0) > tol_cov
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--save")
    g.add_argument("--compare")
    ap.add_argument(
        "--implementation",
        choices=("compiled", "reference"),
        default="compiled",
        help="the pipeline's arithmetic (PosePipeline's implementation)",
    )
    ap.add_argument(
        "--tolerance-mm",
        type=float,
        default=TOL,
        help=f"largest accepted |dt| in --compare, mm (default {TOL:g})",
    )
    ap.add_argument(
        "--tolerance-deg",
        type=float,
        default=TOL,
        help=f"largest accepted rotation difference in --compare, deg (default {TOL:g})",
    )
    ap.add_argument(
        "--tolerance-cov",
        type=float,
        default=TOL,
        help="largest accepted covariance difference in --compare, relative to the "
        f"covariance's largest entry (default {TOL:g})",
    )
    ap.add_argument(
        "--pixel-fit",
        action="store_true",
        help="with the pixel-level fit on (PipelineConfig.pixel_fit); compare with a run "
        "saved with it",
    )
    args = ap.parse_args()
    tols = (
        args.tolerance_mm,
        args.tolerance_deg,
        args.implementation == "reference",
        args.tolerance_cov,
    )
    result = run_both(args.implementation, args.pixel_fit)
    result["pixel_fit_on"] = np.array(args.pixel_fit)
    if args.save:
        np.savez(args.save, **result)
        print(f"saved {len(result['ok'])} frames x 2 modes -> {args.save}")
        return
    with np.load(args.compare) as saved:
        before = dict(saved)
    if bool(before.get("pixel_fit_on", False)) != args.pixel_fit:
        sys.exit(
            f"{args.compare} was saved {'with' if before.get('pixel_fit_on') else 'without'} "
            "--pixel-fit: compare it with a run of the same flag"
        )
    status = compare(before, result, "acquisition", *tols)
    if "tracking_ok" in before:
        tracked = {
            k.removeprefix("tracking_"): v for k, v in result.items() if k.startswith("tracking_")
        }
        old = {
            k.removeprefix("tracking_"): v for k, v in before.items() if k.startswith("tracking_")
        }
        status |= compare(old, tracked, "tracking", *tols)
    sys.exit(status)


if __name__ == "__main__":
    main()
