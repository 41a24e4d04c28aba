"""Evaluation harness for recordings with truth (issue 26: frames of another renderer).

Runs the pipeline over each recording exactly as ``tofpose estimate`` does (it calls
``tofpose.workflows.measurement.estimate`` itself, with its camera / catalog / tracking options, and
records the ``PoseResult`` of every frame on the way), then, against ``/truth``, per
range bin (the distinct true ranges present, or ``--bin-m`` wide bins):

* the pose table: frames, success %, wrong ok poses, confidently wrong ones, frames
  without a pose, the share of ok poses beyond 3 reported sigmas, the mean NEES / 6 and
  the median errors of the successful poses (definitions: ``bench/_foreign_metrics.py``;
  success: <= 1 deg and <= max(20 mm, 0.5 % of range); wrong: ok and > 2 deg or > 2.5 x
  that tolerance; beyond 3 sigma: squared Mahalanobis distance of the 6-vector error
  (rotation vector rad, translation mm) against the reported covariance above
  chi2_6(0.9973) = 20.06), and how many ok poses hold a reflector matched to the wrong
  catalog entry ("mismatch");
* the same for the oracle: the same frames through the same pipeline with the matching
  step replaced by the true correspondences (each measured blob assigned to the
  reflector whose true image it lies on; no triplet fallback; always acquisition mode:
  the tracker's windows are correspondences of their own). What the oracle fails too is
  measurement (or verification); what only the pipeline fails is matching;
* the spread of the errors over the reported sigmas per axis (RMS over ok poses of
  error_k / sigma_k; 1 when the covariance is right);
* per-marker measurement errors by catalog diameter and range bin, over the correctly
  matched reflectors of ok poses: the bias-corrected centroid against the true
  projection of the disc centre (px), the range against the true range to the centre
  (mm): median and 90th percentile of |error|, signed medians (the bias), and the RMS of
  error / the pipeline's sigma.

``bench/oracle.py`` (exact centroids and the simulator's per-pixel range noise) needs the
simulator's surface map, which a foreign recording does not have; this oracle keeps the
pipeline's own measurements and replaces only the correspondences.

Run: ``python bench/foreign.py REC.h5 [REC2.h5 ...] [--tracking] [--camera CAM.json]
[--catalog CAT.json] [--bin-m W] [--no-oracle] [--json OUT.json]``
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path
from unittest import mock

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import fmt, table  # noqa: E402
from bench._foreign_metrics import (  # noqa: E402
    AXES,
    CHI2_6_3SIGMA,
    OUTCOME_HEADERS,
    P_3SIGMA,
    FrameOutcome,
    TrueImages,
    marker_errors,
    marker_summary,
    pose_error,
    range_bins,
    summarise,
    true_correspondences,
    true_images,
)
from bench.rim_sampling import rim_sampling  # noqa: E402
from tofpose.core.geometry import RigidTransform  # noqa: E402
from tofpose.core.threads import single_threaded_blas  # noqa: E402
from tofpose.io import camera_file  # noqa: E402
from tofpose.io.recording import RecordingError, open_recording  # noqa: E402
from tofpose.pipeline import PosePipeline, PoseResult  # noqa: E402
from tofpose.stages.matching.matching import MatchResult  # noqa: E402
from tofpose.workflows import measurement  # noqa: E402

RUNS = ("pipeline", "oracle")

#: what the JSON's numbers mean (``bench/_foreign_metrics.py``)
DEFINITIONS = {
    "pose_error": "rotation vector of R_est R_true^T (rad, camera frame), t_est - t_true (mm)",
    "d2": "e^T Sigma^-1 e against the reported 6x6 covariance (rotation vector rad, t mm)",
    "beyond_3sigma": (
        f"d2 > the chi2_6 quantile at p = erf(3 / sqrt 2) = {P_3SIGMA:.6f}: {CHI2_6_3SIGMA:.4f}"
    ),
    "success": "ok, attitude error <= 1 deg, position error <= max(20 mm, 0.5 % of true range)",
    "wrong": "ok and (attitude error > 2 deg or position error > 2.5 x that tolerance)",
    "confident_wrong": "wrong and beyond_3sigma",
    "nees_over_6": "mean d2 over ok poses / 6 (1 = consistent covariance)",
    "spread_over_sigma": "per axis rx ry rz x y z: sqrt(mean(e_k^2 / Sigma_kk)) over ok poses",
    "markers": "correctly matched reflectors of ok poses; centroid against the true projection "
    "of the disc centre (px), range against the true range to the centre (mm)",
}


# -- the two runs ----------------------------------------------------------------------
def run_estimate(
    rec_path: str | Path,
    *,
    tracking: bool = False,
    camera_path: str | None = None,
    catalog_path: str | None = None,
    progress: bool = True,
    pixel_fit: bool = True,
) -> tuple[list[PoseResult], PosePipeline]:
    """``tofpose.workflows.measurement.estimate`` over a recording (its CSV to a temporary
    file), with the pipelines it builds made to keep each frame's ``PoseResult``:
    (results of the pipeline that measured the CSV's rows, one per frame in order; that
    pipeline, for its camera, catalog, config and calibrations). ``estimate`` first
    learns the range bias with a pipeline of its own (``learned_range_bias``, a sample of
    the frames); the last pipeline built is the one that measures every frame with it."""
    results: dict[int, list[PoseResult]] = {}
    built: list[PosePipeline] = []

    class RecordingPipeline(PosePipeline):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            built.append(self)
            results[id(self)] = []

        def process(self, *args, **kwargs) -> PoseResult:
            r = super().process(*args, **kwargs)
            results[id(self)].append(r)
            return r

    # the pipeline estimate runs is built by tofpose.io.camera_file.pipeline_for
    patched = mock.patch.object(camera_file, "PosePipeline", RecordingPipeline)
    with tempfile.TemporaryDirectory() as tmp, patched:
        summary = measurement.estimate(
            str(rec_path),
            str(Path(tmp) / "poses.csv"),
            catalog_path,
            camera_path,
            progress=progress,
            tracking=tracking,
            pixel_fit=pixel_fit,
        )
    measured = results[id(built[-1])] if built else []
    if len(measured) != summary["frames"]:
        raise RuntimeError(
            f"tofpose.workflows.measurement.estimate's last pipeline processed "
            f"{len(measured)} of {summary['frames']} frames; bench/foreign.py expects one "
            "process() call per frame from the pipeline that writes the CSV"
        )
    if summary["range_bias"]:
        print(f"{Path(rec_path).name}: {summary['range_bias']}", file=sys.stderr)
    return measured, built[-1]


class OraclePipeline(PosePipeline):
    """The pipeline with its matching step replaced by the true correspondences: set
    ``truth`` (``true_images`` of the frame) before each ``process``. Every measured blob
    on a reflector's true image is paired with it (``true_correspondences``); the solver
    (fit, outlier step, verification) runs as in the pipeline, without the triplet
    fallback, which would replace the pairs. ``matched_by_truth`` counts the frames the
    replaced step ran on."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.truth: TrueImages | None = None
        self.matched_by_truth = 0

    def _match(self, meas) -> MatchResult:
        if self.truth is None:
            raise RuntimeError("OraclePipeline.truth must be set before process()")
        self.matched_by_truth += 1
        true_k = true_correspondences(meas.uv_px, meas.range_mm, self.truth)
        k = np.flatnonzero(true_k >= 0)
        pairs = np.column_stack((k, true_k[k])).astype(np.int64).reshape(-1, 2)
        need = self.config.matching.min_matches
        reason = (
            ""
            if len(k) >= need
            else (f"oracle: {len(k)} blob(s) on a reflector's true image, need {need}")
        )
        return MatchResult(
            pairs,
            np.flatnonzero(true_k < 0).tolist(),
            np.zeros((len(true_k), 0)),
            0,
            self.config.matching.alpha_for(meas.y_mm),
            reason,
        )

    def _solve_with_fallback(self, meas, m: MatchResult, active, *, dark_check_all=False):
        return self._solver.solve(m.pairs, meas, m.alpha_mm, active, dark_check_all=dark_check_all)


def run_oracle(rec, pipe: PosePipeline, truth: list[TrueImages], progress: bool = True):
    """The oracle's ``PoseResult`` per frame of an open recording, with the camera,
    catalog, config (tracking off) and calibrations of the estimate's pipeline."""
    config = replace(pipe.config, tracking=replace(pipe.config.tracking, enabled=False))
    oracle = OraclePipeline(
        pipe.camera,
        pipe.catalog,
        config,
        range_correction=pipe.range_correction,
        covariance_scale=pipe.covariance_scale,
    )
    out = []
    for i in tqdm(
        range(rec.n_frames), desc="oracle", unit="frame", disable=not progress, file=sys.stderr
    ):
        gray, dist, t = rec.frame(i)
        oracle.truth = truth[i]
        out.append(oracle.process(gray, dist, t))
    return out, oracle.matched_by_truth


# -- against truth ---------------------------------------------------------------------
def frame_outcome(i: int, r: PoseResult, T: RigidTransform, markers) -> FrameOutcome:
    """A frame's ``FrameOutcome``: ``markers`` its ``marker_errors`` (for the mismatches)."""
    rng = float(np.linalg.norm(T.t_mm))
    if not r.ok:
        return FrameOutcome(i, rng, False, r.reason, n_matched=r.n_matched)
    return FrameOutcome(
        i,
        rng,
        True,
        "",
        pose_error(r.R, r.t_mm, T.R, T.t_mm),
        r.covariance,
        r.n_matched,
        sum(not m.correct for m in markers),
    )


def evaluate(
    rec_path: str | Path,
    *,
    tracking: bool = False,
    camera_path: str | None = None,
    catalog_path: str | None = None,
    bin_width_m: float | None = None,
    oracle: bool = True,
    progress: bool = True,
    pixel_fit: bool = True,
) -> dict:
    """One recording: the pose, spread and per-marker numbers per range bin and run, and
    the per-frame outcomes (``FrameOutcome``), as a dict (``report`` prints it; JSON-ready
    after ``to_json``)."""
    results, pipe = run_estimate(
        rec_path,
        tracking=tracking,
        camera_path=camera_path,
        catalog_path=catalog_path,
        progress=progress,
        pixel_fit=pixel_fit,
    )
    with open_recording(rec_path) as rec:
        if rec.truth_R is None:
            raise SystemExit(f"bench/foreign.py: {rec_path} has no /truth")
        poses = [RigidTransform(R, t) for R, t in zip(rec.truth_R, rec.truth_t_mm, strict=True)]
        # the true images through the recording's camera: what made the frames
        truth = [true_images(rec.camera, pipe.catalog, T) for T in poses]
        runs = {"pipeline": results}
        matched_by_truth = None
        if oracle:
            runs["oracle"], matched_by_truth = run_oracle(rec, pipe, truth, progress)
        try:
            rims = rim_sampling(rec, catalog=pipe.catalog).describe()
        except RecordingError as exc:  # not read: say why
            rims = f"not read ({exc})"
    bins, labels = range_bins(np.linalg.norm(rec.truth_t_mm, axis=1), bin_width_m)
    out = {
        "path": str(rec_path),
        "frames": len(results),
        "tracking": tracking,
        "pixel_fit": pixel_fit,
        "catalog": pipe.catalog.name,
        "bins": labels,
        "oracle_frames_matched": matched_by_truth,
        "rim_sampling": rims,
        "pose": [],
        "markers": [],
        "outcomes": {},
        "reasons": {},
    }
    diam = pipe.catalog.diameters_mm
    for run, res in runs.items():
        markers = [
            marker_errors(r, truth[i], pipe.catalog, int(bins[i])) for i, r in enumerate(res)
        ]
        outcomes = [frame_outcome(i, r, poses[i], markers[i]) for i, r in enumerate(res)]
        out["outcomes"][run] = outcomes
        out["reasons"][run] = Counter(_reason_kind(o.reason) for o in outcomes if not o.ok)
        for b, label in [*enumerate(labels), (None, "all")]:
            sel = [o for o in outcomes if b is None or bins[o.frame] == b]
            out["pose"].append({"bin": label, "run": run, **summarise(sel)})
        for b, label in enumerate(labels):
            for d in sorted(set(diam.tolist())):
                errs = [e for m in markers for e in m if e.bin == b and e.diameter_mm == d]
                seen = sum(
                    int(np.sum(truth[i].in_view & (diam == d)))
                    for i, r in enumerate(res)
                    if r.ok and bins[i] == b
                )
                out["markers"].append(
                    {"bin": label, "run": run, "diameter_mm": d, **marker_summary(errs, seen)}
                )
    return out


def _reason_kind(reason: str) -> str:
    """A failure reason with its numbers replaced by '#', so that alike reasons count
    together."""
    return re.sub(r"\d+(\.\d+)?", "#", reason)[:90]


# -- printing --------------------------------------------------------------------------
def _int(x: int) -> str:
    return "-" if x < 0 else str(x)


def report(ev: dict) -> str:
    """The tables of one evaluated recording (``evaluate``)."""
    mode = "tracking" if ev["tracking"] else "acquisition"
    mode += " mode" if ev.get("pixel_fit") else " mode, centroid pose only (`--no-pixel-fit`)"
    name = Path(ev["path"]).name
    head = f"### {name}: {ev['frames']} frames, {mode}, catalog {ev['catalog']!r}"
    n_truth = ev["oracle_frames_matched"]
    if n_truth is not None:
        head += f"; the oracle matched {n_truth} frames by truth"
        if n_truth < ev["frames"]:
            head += " (the others had too few candidate blobs)"
    lines = [
        head,
        "",
        f"Rendering, read at the true poses (`bench/rim_sampling.py`): {ev['rim_sampling']}.",
        "",
        "Poses (success: <= 1 deg and <= max(20 mm, 0.5 % range); wrong: ok and "
        "> 2 deg or > 2.5x that; conf. wrong: wrong and d2 > "
        f"chi2_6({P_3SIGMA:.4f}) = {CHI2_6_3SIGMA:.2f}; NEES/6: mean d2 / 6, 1 = "
        "consistent; medians over successful poses; mismatch: ok poses with a "
        "reflector matched to the wrong catalog entry)",
        "",
    ]
    rows = [
        [
            p["bin"],
            p["run"],
            str(p["frames"]),
            fmt(p["success_pct"], 0),
            str(p["wrong"]),
            str(p["confident_wrong"]),
            str(p["no_pose"]),
            fmt(p["beyond_3sigma_pct"], 0),
            fmt(p["nees_over_6"], 2),
            fmt(p["median_attitude_deg"], 3),
            fmt(p["median_position_mm"], 1),
            _int(p["mismatch_frames"]),
        ]
        for p in ev["pose"]
    ]
    lines.append(
        table(
            [
                "range",
                "run",
                "frames",
                *OUTCOME_HEADERS,
                "mismatch",
            ],
            rows,
        )
    )
    lines += [
        "",
        "Error spread / reported sigma per axis (RMS over ok poses of e_k / "
        "sigma_k; rotation vector in the camera frame, translation mm; 1 = right)",
        "",
    ]
    rows = [
        [
            p["bin"],
            p["run"],
            str(p["frames"] - p["no_pose"]),
            *(fmt(v, 2) for v in p["spread_over_sigma"]),
        ]
        for p in ev["pose"]
    ]
    lines.append(table(["range", "run", "ok", *AXES], rows))
    lines += [
        "",
        "Per-marker errors of correctly matched reflectors in ok poses (centroid: "
        "bias-corrected, against the true projection of the disc centre; range: "
        "against the true range to the centre; du, dv, range bias: signed medians; "
        "e/sigma: RMS of error over the pipeline's sigma)",
        "",
    ]
    rows = [
        [
            m["bin"],
            m["run"],
            f"{m['diameter_mm']:g}",
            str(m["in_view"]),
            str(m["matched"]),
            str(m["mismatched"]),
            fmt(m["centroid_p50_px"], 3),
            fmt(m["centroid_p90_px"], 3),
            fmt(m["du_median_px"], 3),
            fmt(m["dv_median_px"], 3),
            fmt(m["centroid_z_rms"], 1),
            fmt(m["range_p50_mm"], 1),
            fmt(m["range_p90_mm"], 1),
            fmt(m["range_median_mm"], 1),
            fmt(m["range_z_rms"], 1),
        ]
        for m in ev["markers"]
    ]
    lines.append(
        table(
            [
                "range",
                "run",
                "diam mm",
                "in view",
                "matched",
                "mismatch",
                "c p50 px",
                "c p90 px",
                "du px",
                "dv px",
                "c e/sigma",
                "r p50 mm",
                "r p90 mm",
                "r bias mm",
                "r e/sigma",
            ],
            rows,
        )
    )
    for run, reasons in ev["reasons"].items():
        if reasons:
            lines += ["", f"No pose ({run}):"]
            lines += [f"  {n} x {k}" for k, n in reasons.most_common()]
    return "\n".join(lines)


def to_json(ev: dict) -> dict:
    """``evaluate``'s dict with the outcomes as records and NaN as null."""

    def clean(x):
        if isinstance(x, np.generic):
            x = x.item()
        if isinstance(x, float):
            return x if math.isfinite(x) else None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    doc = {k: v for k, v in ev.items() if k not in ("outcomes", "reasons")}
    doc["reasons"] = {run: dict(c) for run, c in ev["reasons"].items()}
    doc["frames_detail"] = {
        run: [o.to_dict() for o in outs] for run, outs in ev["outcomes"].items()
    }
    return clean(doc)


def main(argv: list[str] | None = None) -> int:
    single_threaded_blas()  # as the tofpose command
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="+", help="recordings with /truth (HDF5)")
    ap.add_argument("--tracking", action="store_true", help="the estimate's tracking mode")
    ap.add_argument("--camera", help="camera JSON for the estimate (default: the recording's)")
    ap.add_argument("--catalog", help="catalog JSON for the estimate (default: the recording's)")
    ap.add_argument(
        "--bin-m",
        type=float,
        default=None,
        help="range bins this wide (default: the distinct ranges present)",
    )
    ap.add_argument("--no-oracle", action="store_true", help="skip the true-correspondence run")
    ap.add_argument(
        "--pixel-fit",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="the estimate's --pixel-fit / --no-pixel-fit (default: on, as estimate's)",
    )
    ap.add_argument("--json", help="write every number and the per-frame outcomes here")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    docs = []
    for path in args.recordings:
        try:
            ev = evaluate(
                path,
                tracking=args.tracking,
                camera_path=args.camera,
                catalog_path=args.catalog,
                bin_width_m=args.bin_m,
                oracle=not args.no_oracle,
                progress=not args.quiet,
                pixel_fit=args.pixel_fit,
            )
        except RecordingError as exc:
            print(f"bench/foreign.py: {exc}", file=sys.stderr)
            return 2
        print(report(ev), "\n", flush=True)
        docs.append(to_json(ev))
    if args.json:
        Path(args.json).write_text(
            json.dumps({"definitions": DEFINITIONS, "recordings": docs}, indent=1) + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
