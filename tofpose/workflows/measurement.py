"""``tofpose estimate``, ``calibrate-range`` and ``calibrate-covariance`` as functions:
the pipeline over a recording, and the two calibrations fitted against its reference
poses."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tofpose.calibration.covariance import auto_knots, fit_covariance_scale, pose_nees
from tofpose.calibration.range import fit_range_correction
from tofpose.config import config_for_camera
from tofpose.core.geometry import RigidTransform
from tofpose.core.tof import unambiguous_range_mm
from tofpose.io.camera_file import (
    learned_range_bias,
    load_camera,
    pipeline_for,
    read_camera_text,
    resolve_pixel_fit,
)
from tofpose.io.pose_csv import CSV_COLUMNS, FILTER_COLUMNS, HeldRows, pose_row, result_pose
from tofpose.io.recording import Recording, open_recording
from tofpose.pipeline import PipelineConfig, PosePipeline
from tofpose.sim.pixel_truth import true_pixel_distances


def _reference(rec: Recording, reference: str, rec_path: str) -> tuple[np.ndarray, np.ndarray]:
    """The recording's reference poses (``/truth`` or ``/lab_truth``): R (N, 3, 3), t (N, 3)."""
    R_all, t_all = (
        (rec.truth_R, rec.truth_t_mm)
        if reference == "truth"
        else (rec.lab_truth_R, rec.lab_truth_t_mm)
    )
    if R_all is None or t_all is None:  # a recording holds both or neither
        raise SystemExit(f"tofpose: {rec_path} has no /{reference}: nothing to calibrate against")
    return R_all, t_all


def calibrate_covariance(
    rec_path: str,
    out: str,
    camera_path: str | None,
    reference: str,
    knots_mm: list[float] | None,
    progress: bool = True,
) -> str:
    """Run the pipeline over a recording of the known target (with the camera's range
    correction, if any), compare each pose and its covariance with the reference, fit
    the covariance's factor per range (``tofpose.calibration.covariance``) and write the
    camera JSON with it."""
    with open_recording(rec_path) as rec:
        R_all, t_all = _reference(rec, reference, rec_path)
        if rec.catalog is None:
            raise SystemExit(f"tofpose: {rec_path} has no /catalog: the target is unknown")
        camera, correction = rec.camera, None
        if camera_path:
            camera, correction, _ = load_camera(read_camera_text(camera_path))
        config = config_for_camera(
            PipelineConfig(),
            width=camera.width,
            height=camera.height,
            count_scale=camera.count_scale,
        )
        pipe = PosePipeline(camera, rec.catalog, config, range_correction=correction)
        ranges, nees = [], []
        for i in tqdm(
            range(rec.n_frames),
            desc="calibrate-covariance",
            unit="frame",
            disable=not progress,
            file=sys.stderr,
        ):
            gray, dist, t = rec.frame(i)
            r = pipe.process(gray, dist, t)
            if r.ok and r.covariance is not None:
                if r.R is None or r.t_mm is None:
                    raise RuntimeError(f"frame {i}: a result marked ok has no pose (R, t_mm)")
                ranges.append(float(np.linalg.norm(t_all[i])))
                nees.append(pose_nees(r.R, r.t_mm, r.covariance, R_all[i], t_all[i]))
    fit = fit_covariance_scale(ranges, nees, knots_mm or auto_knots(ranges))
    doc = {**camera.to_dict(), "covariance_scale": fit.scale.to_dict()}
    if correction is not None:
        doc["range_correction"] = correction.to_dict()
    Path(out).write_text(json.dumps(doc, indent=1) + "\n")
    per_knot = "; ".join(
        f"{k:.0f} mm: {n} frames ({o} failed poses left out), mean NEES {m:.2f} -> x{f:.3g}"
        for k, n, o, m, f in zip(
            fit.scale.ranges_mm,
            fit.frames,
            fit.outliers,
            fit.mean_nees,
            fit.scale.factors,
            strict=True,
        )
    )
    return f"{len(nees)} of {rec.n_frames} frames with a pose; {per_knot} -> {out}"


def calibrate_range(
    rec_path: str,
    out: str,
    reference: str,
    modulation_mhz: float | None,
    progress: bool = True,
) -> str:
    """Fit the range correction from a recording of the known target with a reference
    pose per frame (``/truth`` or ``/lab_truth``); write the camera JSON with it.
    ``modulation_mhz``: the frequency whose period the cyclic error has (None: the
    recording's camera's)."""
    with open_recording(rec_path) as rec:
        if modulation_mhz is None:
            modulation_mhz = rec.camera.modulation_frequency_hz / 1e6
        R_all, t_all = _reference(rec, reference, rec_path)
        if rec.catalog is None:
            raise SystemExit(f"tofpose: {rec_path} has no /catalog: the target's shape is unknown")

        def samples():
            for i in tqdm(
                range(rec.n_frames),
                desc="calibrate-range",
                unit="frame",
                disable=not progress,
                file=sys.stderr,
            ):
                gray, dist, _ = rec.frame(i)
                T = RigidTransform(R_all[i], t_all[i])
                if T.t_mm[2] <= 0:
                    continue
                truth = true_pixel_distances(rec.camera, rec.catalog, T)
                yield dist.astype(float), gray.astype(float), truth

        fit = fit_range_correction(samples(), unambiguous_range_mm(modulation_mhz))
        doc = {**rec.camera.to_dict(), "range_correction": fit.correction.to_dict()}
    Path(out).write_text(json.dumps(doc, indent=1) + "\n")
    c = fit.correction
    span = c.calibrated_span_mm
    if span is None:  # fit_range_correction sets it from the samples it used
        raise RuntimeError("the fitted range correction has no calibrated span")
    harm = ", ".join(f"{np.hypot(a, b):.2f}" for a, b in c.harmonics_mm)
    return (
        f"{fit.n_frames} frames, {fit.n_samples} pixel samples: constant {c.offset_mm:.2f} mm, "
        f"cyclic amplitudes {harm} mm, amplitude term {c.amplitude_mm_per_decade:.2f} "
        f"mm/decade, {fit.pixels_with_offset} per-pixel offsets; residual RMS "
        f"{fit.rms_before_mm:.2f} -> {fit.rms_after_mm:.2f} mm; calibrated span "
        f"{span[0]:.0f}-{span[1]:.0f} mm -> {out}"
    )


def estimate(
    rec_path: str,
    out_csv: str,
    catalog_path: str | None,
    camera_path: str | None,
    progress: bool = True,
    tracking: bool = False,
    filter_state: bool = False,
    pixel_fit: bool | None = None,
    causal_filter: bool = False,
    learn_range_bias: bool | None = None,
) -> dict[str, float | str | bool]:
    """Run the pipeline over a recording and write the CSV; returns summary numbers.
    ``tracking``: the pipeline's tracking mode (faster on a continuous recording);
    ``filter_state``: run the relative-state filter over the poses and add
    ``FILTER_COLUMNS``, each pose measured on its own frame (``pipeline_for``'s
    ``moving``): the state at each frame from all the recording's poses
    (``tofpose.lab.smoothing``; the rows are held until the last frame), or with
    ``causal_filter`` from the poses up to it, as the live loop has it (empty until its
    first pose); ``pixel_fit``: refine each pose on the markers' pixels
    (``PipelineConfig.pixel_fit``; None: on unless the camera JSON carries a covariance
    scale, ``resolve_pixel_fit``; off in the live loop, whose frame budget it does not
    fit); ``learn_range_bias``: first learn the mean and spread of the camera's range
    offsets over the recording (``io.camera_file.learned_range_bias``) and measure every
    frame with them as the offset's prior (None: with the pixel fit; the summary's
    "range_bias" says what was learned)."""
    pixel_fit = resolve_pixel_fit(pixel_fit, camera_path)
    learn = pixel_fit if learn_range_bias is None else learn_range_bias
    with open_recording(rec_path) as rec:
        learned = (
            learned_range_bias(
                rec, rec_path, catalog_path, camera_path, pixel_fit=pixel_fit, progress=progress
            )
            if learn
            else None
        )
        pipe = pipeline_for(
            rec,
            rec_path,
            catalog_path,
            camera_path,
            tracking,
            pixel_fit=pixel_fit,
            moving=filter_state,  # a filter follows a motion: poses from single frames
            range_bias=learned,
        )
        n_ok = 0
        held = HeldRows()  # with the filter: held for its pass over every pose
        with open(out_csv, "w", newline="") as fh:
            wr = csv.writer(fh)
            wr.writerow(CSV_COLUMNS + (FILTER_COLUMNS if filter_state else ()))
            bar = tqdm(
                total=rec.n_frames,
                desc="estimate",
                unit="frame",
                disable=not progress,
                file=sys.stderr,
            )
            for first, (grays, dists, block_times) in rec.blocks():  # aligned to the chunks
                for k, t in enumerate(block_times.tolist()):
                    r = pipe.process(grays[k], dists[k], t)
                    n_ok += int(r.ok)
                    row = pose_row(first + k, t, r)
                    if not filter_state:
                        wr.writerow(row)
                        continue
                    held.add(row, t, result_pose(r))
                bar.update(len(block_times))
            bar.close()
            if filter_state:
                held.write(wr, causal=causal_filter, progress=progress)
        return {
            "frames": rec.n_frames,
            "ok": n_ok,
            "pixel_fit": pixel_fit,
            "range_bias": ""
            if learned is None
            # the sigmas the frames were measured with (pipeline_for capped them)
            else learned.summary(
                pipe.config.range_bias_sigma_mm, pipe.config.calibrated_range_bias_sigma_mm
            ),
        }
