"""The ``tofpose`` command: estimate poses from recordings, simulate, render, demo."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tofpose.calibration.covariance import (
    auto_knots,
    fit_covariance_scale,
    pose_nees,
)
from tofpose.calibration.range import fit_range_correction
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog, paper_target
from tofpose.core.geometry import RigidTransform, facing_euler_deg, rotation_angle_deg
from tofpose.core.threads import single_threaded_blas
from tofpose.core.tof import unambiguous_range_mm
from tofpose.io.camera_file import load_camera, pipeline_for, read_text_file
from tofpose.io.interop.topics import DISTANCE as DISTANCE_TOPIC
from tofpose.io.interop.topics import GRAY as GRAY_TOPIC
from tofpose.io.pose_csv import CSV_COLUMNS, FILTER_COLUMNS, filter_row, pose_row
from tofpose.io.recording import RecordingError, RecordingWriter, open_recording
from tofpose.lab.relative_state import RelativeStateConfig, RelativeStateFilter
from tofpose.pipeline import PosePipeline
from tofpose.sim.pixel_truth import true_pixel_distances


def _reference(rec, reference: str, rec_path: str) -> tuple[np.ndarray, np.ndarray]:
    """The recording's reference poses (``/truth`` or ``/lab_truth``): R (N, 3, 3), t (N, 3)."""
    R_all, t_all = (
        (rec.truth_R, rec.truth_t_mm)
        if reference == "truth"
        else (rec.lab_truth_R, rec.lab_truth_t_mm)
    )
    if R_all is None:
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
            camera, correction, _ = load_camera(read_text_file(camera_path, "camera"))
        pipe = PosePipeline(camera, rec.catalog, range_correction=correction)
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
    rec_path: str, out: str, reference: str, modulation_mhz: float, progress: bool = True
) -> str:
    """Fit the range correction from a recording of the known target with a reference
    pose per frame (``/truth`` or ``/lab_truth``); write the camera JSON with it."""
    with open_recording(rec_path) as rec:
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
    harm = ", ".join(f"{np.hypot(a, b):.2f}" for a, b in c.harmonics_mm)
    return (
        f"{fit.n_frames} frames, {fit.n_samples} pixel samples: constant {c.offset_mm:.2f} mm, "
        f"cyclic amplitudes {harm} mm, amplitude term {c.amplitude_mm_per_decade:.2f} "
        f"mm/decade, {fit.pixels_with_offset} per-pixel offsets; residual RMS "
        f"{fit.rms_before_mm:.2f} -> {fit.rms_after_mm:.2f} mm; calibrated span "
        f"{c.calibrated_span_mm[0]:.0f}-{c.calibrated_span_mm[1]:.0f} mm -> {out}"
    )


def estimate(
    rec_path: str,
    out_csv: str,
    catalog_path: str | None,
    camera_path: str | None,
    progress: bool = True,
    tracking: bool = False,
    filter_state: bool = False,
) -> dict[str, float]:
    """Run the pipeline over a recording and write the CSV; returns summary numbers.
    ``tracking``: the pipeline's tracking mode (faster on a continuous recording);
    ``filter_state``: run the relative-state filter over the poses and add
    ``FILTER_COLUMNS`` (empty until its first pose)."""
    with open_recording(rec_path) as rec:
        pipe = pipeline_for(rec, rec_path, catalog_path, camera_path, tracking)
        n_ok = 0
        model = RelativeStateConfig.constant_acceleration()
        rel = RelativeStateFilter(model) if filter_state else None
        with open(out_csv, "w", newline="") as fh:
            wr = csv.writer(fh)
            wr.writerow(CSV_COLUMNS + (FILTER_COLUMNS if rel else ()))
            bar = tqdm(
                total=rec.n_frames,
                desc="estimate",
                unit="frame",
                disable=not progress,
                file=sys.stderr,
            )
            for first, (grays, dists, times) in rec.blocks():  # reads aligned to the chunks
                for k, t in enumerate(times.tolist()):
                    r = pipe.process(grays[k], dists[k], t)
                    n_ok += int(r.ok)
                    row = pose_row(first + k, t, r)
                    if rel is not None:
                        row += filter_row(rel, t, *((r.R, r.t_mm, r.covariance) if r.ok else ()))
                    wr.writerow(row)
                bar.update(len(times))
            bar.close()
        return {"frames": rec.n_frames, "ok": n_ok}


def simulate(
    scenario_name: str,
    n_frames: int,
    out: str,
    seed: int,
    catalog_path: str | None,
    progress: bool = True,
) -> None:
    from tofpose.sim.scenarios import get_scenario, run_scenario

    scenario = get_scenario(scenario_name)
    catalog = (
        Catalog.from_json(read_text_file(catalog_path, "catalog"))
        if catalog_path
        else paper_target()
    )
    camera = CameraModel()
    with RecordingWriter(out, camera, catalog, with_truth=True, with_lab_truth=True) as w:
        for bf in tqdm(
            run_scenario(scenario, n_frames, seed=seed, catalog=catalog),
            total=n_frames,
            desc=f"simulate {scenario_name}",
            unit="frame",
            disable=not progress,
            file=sys.stderr,
        ):
            w.append(
                bf.frame.gray,
                bf.frame.distance_mm,
                bf.time_s,
                bf.T_true.R,  # /truth: the pose the simulator rendered
                bf.T_true.t_mm,
                lab_R_camera_target=bf.T_lab_truth.R,  # /lab_truth: encoders + nominal
                lab_t_camera_target_mm=bf.T_lab_truth.t_mm,
            )


def render_pngs(scenario_name: str, prefix: str, seed: int) -> list[str]:
    """Write PREFIX-gray.png and PREFIX-distance.png of a scenario's first frame."""
    import cv2

    from tofpose.sim.scenarios import get_scenario, run_scenario

    bf = next(run_scenario(get_scenario(scenario_name), 1, seed=seed))
    g = bf.frame.gray.astype(np.float64)
    g8 = np.clip(255 * np.sqrt(g / max(g.max(), 1)), 0, 255).astype(np.uint8)  # gamma 0.5
    d = bf.frame.distance_mm
    valid = np.isfinite(d)
    lo, hi = np.percentile(d[valid], [2, 98]) if valid.any() else (0, 1)
    d8 = np.zeros(d.shape, np.uint8)
    d8[valid] = np.clip(255 * (d[valid] - lo) / max(hi - lo, 1e-6), 0, 255).astype(np.uint8)
    color = cv2.applyColorMap(d8, cv2.COLORMAP_TURBO)
    color[~valid] = 0
    scale = 2
    out = []
    for name, img in (("gray", g8), ("distance", color)):
        path = f"{prefix}-{name}.png"
        big = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        cv2.imwrite(path, big)
        out.append(path)
    return out


def demo(n_frames: int = 48, seed: int = 1) -> int:
    """Simulate a short attitude-grid recording, estimate it, print estimate vs truth."""
    with tempfile.TemporaryDirectory() as tmp:
        rec, out = Path(tmp) / "demo.h5", Path(tmp) / "poses.csv"
        print(f"simulating {n_frames} frames of the 'attitude-grid' scenario ...", flush=True)
        simulate("attitude-grid", n_frames, str(rec), seed, None)
        estimate(str(rec), str(out), None, None)
        with open_recording(rec) as r, open(out) as fh:
            rows = list(csv.DictReader(fh))
            hdr = (
                f"{'frame':>5} {'ok':>2} {'n':>2} | {'x_mm':>8} {'y_mm':>8} {'z_mm':>9} "
                f"{'pitch':>8} {'yaw':>7} {'roll':>7} | {'dpos_mm':>7} {'dang_deg':>8}"
            )
            print(hdr)
            print("-" * len(hdr))
            errs = []
            for i in range(0, r.n_frames, max(1, r.n_frames // 24)):
                row = rows[i]
                R_t, t_t = r.truth_R[i], r.truth_t_mm[i]
                e_t = facing_euler_deg(R_t)
                print(
                    f"{i:>5} {'':>2} {'':>2} | {t_t[0]:8.2f} {t_t[1]:8.2f} {t_t[2]:9.2f} "
                    f"{e_t[0]:8.3f} {e_t[1]:7.3f} {e_t[2]:7.3f} |   truth"
                )
                if row["ok"] == "1":
                    t_m = np.array([float(row[k]) for k in ("x_mm", "y_mm", "z_mm")])
                    q = [float(row[k]) for k in ("qw", "qx", "qy", "qz")]
                    from scipy.spatial.transform import Rotation

                    R_m = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
                    dp, da = np.linalg.norm(t_m - t_t), rotation_angle_deg(R_m, R_t)
                    errs.append((dp, da))
                    print(
                        f"{'':>5} {1:>2} {row['n_matched']:>2} | {t_m[0]:8.2f} {t_m[1]:8.2f} "
                        f"{t_m[2]:9.2f} {float(row['pitch_deg']):8.3f} "
                        f"{float(row['yaw_deg']):7.3f} {float(row['roll_deg']):7.3f} | "
                        f"{dp:7.2f} {da:8.3f}"
                    )
                else:
                    print(f"{'':>5} {0:>2} {row['n_matched']:>2} | (no pose)")
            n_ok = sum(1 for row in rows if row["ok"] == "1")
            print(f"\n{n_ok}/{len(rows)} frames with a pose", end="")
            if errs:
                e = np.array(errs)
                print(f"; median error {np.median(e[:, 0]):.2f} mm, {np.median(e[:, 1]):.3f} deg")
            else:
                print()
    return 0


def export_file(args: argparse.Namespace) -> str:
    """``tofpose export mcap``: the recording, and with ``--estimate`` each frame's pose."""
    from tofpose.io.interop.mcap_export import export_mcap  # lazy: foxglove-sdk loads a runtime

    with open_recording(args.recording) as rec:
        pipe = (
            pipeline_for(rec, args.recording, args.catalog, args.camera, args.tracking)
            if args.estimate
            else None
        )
        s = export_mcap(rec, args.out, pipe, overwrite=args.force, previews=args.previews)
    poses = f", {s['ok']} with a pose" if args.estimate else ""
    return f"{s['frames']} frames{poses} -> {args.out}"


def import_file(args: argparse.Namespace) -> str:
    """``tofpose import mcap``."""
    from tofpose.io.interop.mcap_import import import_mcap

    s = import_mcap(
        args.file,
        args.out,
        gray_topic=args.gray_topic,
        distance_topic=args.distance_topic,
        overwrite=args.force,
    )
    return f"{s['frames']} frames -> {args.out}"


def _cluster_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int,
        help="worker processes of a LocalCluster on this machine (default: its cores)",
    )
    g.add_argument("--scheduler", help="address of a running Dask scheduler, tcp://host:8786")


def study(args) -> int:
    """``tofpose study``: print the example spec, or run a spec into --out."""
    from tofpose.batch.cluster import ClusterError
    from tofpose.study.run import StudyCancelledError, run_study
    from tofpose.study.spec import EXAMPLE, StudySpec, StudySpecError
    from tofpose.study.store import StudyStoreError

    if args.example:
        print(json.dumps(EXAMPLE, indent=2))
        return 0
    if not args.spec or not args.out:
        print("tofpose study: give a SPEC and --out DIR (or --example)", file=sys.stderr)
        return 2
    try:
        spec = StudySpec.from_json(read_text_file(args.spec, "study spec"), args.spec)
        summary = run_study(spec, args.out, workers=args.workers, scheduler=args.scheduler)
    except (StudySpecError, StudyStoreError, ClusterError) as exc:
        print(f"tofpose study: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, StudyCancelledError):
        print(
            f"tofpose study: interrupted; {args.out} holds the chunks that finished "
            "(study.json: incomplete); run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    a = summary["all"]
    print(
        f"{summary['frames_stored']} frames in {len(spec.cells)} cells: success "
        f"{a['success_pct']:.1f} %, {a['wrong']} wrong, {a['confidently_wrong']} confidently "
        f"wrong -> {Path(args.out) / 'report.html'}"
    )
    return 0


def reprocess(args) -> int:
    """``tofpose reprocess``: recordings in chunks on Dask, one CSV each."""
    from tofpose.batch.cluster import ClusterError
    from tofpose.batch.reprocess import ReprocessError, Settings
    from tofpose.batch.reprocess import reprocess as run

    settings = Settings(args.camera, args.catalog, args.tracking)
    try:
        s = run(
            args.recordings,
            args.out,
            settings=settings,
            workers=args.workers,
            scheduler=args.scheduler,
            filter_state=args.filter,
            chunk_frames=args.chunk_frames,
        )
    except (RecordingError, ReprocessError, ClusterError) as exc:
        print(f"tofpose reprocess: {exc}", file=sys.stderr)
        return 2
    for r in s["recordings"]:
        print(f"{r['ok']}/{r['frames']} frames with a pose -> {Path(args.out) / r['csv']}")
    fps = s["run"]["frames_per_s"]
    print(f"{s['run']['frames']} frames on {s['run']['workers']} workers, {fps:.1f} frames/s")
    return 0


def compare(args) -> int:
    """``tofpose compare``: two runs' poses frame by frame."""
    from tofpose.batch.compare import CompareError, compare_runs

    try:
        s = compare_runs(args.run_a, args.run_b, args.out)
    except CompareError as exc:
        print(f"tofpose compare: {exc}", file=sys.stderr)
        return 2
    for name, r in s["recordings"].items():
        att, pos = r["attitude_diff_deg"], r["position_diff_mm"]
        print(
            f"{name}: {r['frames']} frames, poses {r['ok_a']} -> {r['ok_b']} "
            f"(gained {r['gained']}, lost {r['lost']}); attitude difference p50 "
            f"{att['p50']} / max {att['max']} deg, position p50 {pos['p50']} / max "
            f"{pos['max']} mm"
        )
    print(f"-> {Path(args.out) / 'compare.json'}")
    return 0


def _add_measurement_commands(sub) -> None:
    """The subcommands estimate, calibrate-range and calibrate-covariance, on ``sub``."""
    p = sub.add_parser("estimate", help="estimate the pose of every frame of a recording")
    p.add_argument("recording")
    p.add_argument("--catalog", help="catalog JSON (default: the recording's)")
    p.add_argument("--camera", help="camera JSON (default: the recording's)")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument(
        "--tracking",
        action="store_true",
        help="tracking mode: look for reflectors near their last position",
    )
    p.add_argument(
        "--filter",
        action="store_true",
        help="add the relative-state filter's angular rate and velocity with "
        "their 1-sigma (rate_*, vel_*, sigma_rate_*, sigma_vel_*)",
    )
    p = sub.add_parser(
        "calibrate-range",
        help="fit the camera's range correction from a recording of the known target",
    )
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="camera JSON with its range_correction")
    p.add_argument(
        "--reference",
        choices=("truth", "lab_truth"),
        default="truth",
        help="reference pose per frame (default: /truth)",
    )
    p.add_argument(
        "--modulation-mhz",
        type=float,
        default=6.0,
        help="the recording's modulation frequency (default 6 MHz)",
    )
    p = sub.add_parser(
        "calibrate-covariance",
        help="fit the camera's covariance factor per range from a recording of the known target",
    )
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="camera JSON with its covariance_scale")
    p.add_argument(
        "--camera",
        help="camera JSON to start from, e.g. with its range correction "
        "(default: the recording's camera)",
    )
    p.add_argument(
        "--reference",
        choices=("truth", "lab_truth"),
        default="truth",
        help="reference pose per frame (default: /truth); its own error must be "
        "well below the pose's",
    )
    p.add_argument(
        "--knots-mm",
        type=lambda v: [float(x) for x in v.split(",")],
        help="target distances of the factors, comma separated (default: every "
        "1.5x over the recording's range, each with >= 20 frames)",
    )


def _add_simulation_commands(sub) -> None:
    """The subcommands simulate, render, demo, on the subparsers ``sub``."""
    p = sub.add_parser("simulate", help="write a simulated recording with ground truth")
    p.add_argument("--scenario", required=True)
    p.add_argument("--frames", type=int, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--catalog")
    p = sub.add_parser("render", help="write gray and distance PNGs of a scenario frame")
    p.add_argument("--scenario", default="stability-697")
    p.add_argument("--out-prefix", required=True)
    p.add_argument("--seed", type=int, default=0)
    p = sub.add_parser("demo", help="simulate, estimate and print estimate vs truth")
    p.add_argument("--frames", type=int, default=48)


def _add_server_commands(sub) -> None:
    """The subcommands serve, report, keys, record, emulate, on the subparsers ``sub``."""
    p = sub.add_parser(
        "serve", help="run the server (simulated devices by default); settings also from TOFPOSE_*"
    )
    p.add_argument("--host", help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (default 8000)")
    p.add_argument("--db", dest="database_url", help="SQLAlchemy URL (default SQLite in data dir)")
    p.add_argument("--data-dir", help="data directory (default ./data)")
    p.add_argument("--camera", help="'sim', 'replay:REC.h5' or 'tofcam660:ADDRESS'")
    p.add_argument("--motion", help="'sim', 'none' or 'scpi:HOST:PORT'")
    p.add_argument("--rate", dest="replay_rate_hz", type=float, help="replay rate, Hz")
    p.add_argument("--viser-port", type=int, help="port of the 3-D scene (default 8080, 0 = any)")
    p.add_argument(
        "--no-viser",
        dest="viser",
        action="store_false",
        default=None,
        help="do not run the 3-D scene",
    )
    p.add_argument(
        "--foxglove-port",
        type=int,
        help="publish the live stream to Foxglove on this port (default off; "
        "0 = any free port; docs/interop.md)",
    )
    p = sub.add_parser("report", help="write a campaign's accuracy report from the database")
    p.add_argument("campaign_id", type=int)
    p.add_argument("--db", required=True, help="SQLAlchemy URL, e.g. sqlite:///data/tofpose.db")
    p.add_argument("--format", choices=("html", "pdf", "csv", "json"), default="html")
    p.add_argument("--reference", choices=("lab", "exact"), default="lab")
    p.add_argument(
        "--calibration",
        type=int,
        metavar="ID",
        help="reference = encoders + this stored bench calibration (as the API's ?calibration=ID)",
    )
    p.add_argument("--out", required=True, help="output file")
    p = sub.add_parser("keys", help="API keys of the server's database: create, list, revoke")
    p.add_argument("--data-dir", help="data directory (default ./data)")
    p.add_argument("--db", dest="database_url", help="SQLAlchemy URL (default SQLite in data dir)")
    keys = p.add_subparsers(dest="action", required=True)
    q = keys.add_parser("create", help="make a key and print it (once: only its hash is kept)")
    q.add_argument("name")
    q.add_argument(
        "--scope",
        required=True,
        choices=("read", "operate", "admin"),
        help="read: live data and reports; operate: also every state change; "
        "admin: also keys, the audit trail and deletions",
    )
    keys.add_parser("list", help="every key: name, scope, created, revoked")
    q = keys.add_parser("revoke", help="revoke a key (a running server follows within 5 s)")
    q.add_argument("name")
    p = sub.add_parser(
        "record",
        help="record a running server's live stream to HDF5 (POST /api/recordings; docs/server.md)",
    )
    p.add_argument("--duration", type=float, required=True, help="seconds to record")
    p.add_argument("--name", help="what it is for (default: 'tofpose record' and the UTC time)")
    p.add_argument("--url", default="http://127.0.0.1:8000", help="the server")
    p.add_argument(
        "--key",
        help="API key of scope operate or admin (default: $TOFPOSE_API_KEY, else the key file)",
    )
    p.add_argument("--key-file", default="data/api_token", help="default data/api_token")
    p.add_argument("--out", help="the HDF5 file to write (default: NAME-ID.h5 here)")
    p.add_argument(
        "--no-download",
        dest="download",
        action="store_false",
        help="leave the recording on the server and print its URL",
    )
    p = sub.add_parser("emulate", help="run device emulators over a simulated lab")
    emu = p.add_subparsers(dest="device", required=True)
    for name, text in (
        ("camera", "ESPROS TOFcam-660 protocol (TCP 50660, UDP images to port 45454)"),
        ("table", "SCPI rate-table controller (ACUTROL3000-style)"),
        ("lab", "both, over one simulated lab (moving the table changes what the camera sees)"),
    ):
        q = emu.add_parser(name, help=text)
        if name == "camera":
            q.add_argument("--address", default="127.0.0.2", help="loopback address of its own")
        if name == "lab":
            q.add_argument("--camera-address", default="127.0.0.2")
            q.add_argument("--table-port", type=int, default=5025)
        if name != "camera":
            q.add_argument("--host", default="127.0.0.1", help="rate-table bind address")
        if name == "table":
            q.add_argument("--port", type=int, default=5025)
        q.add_argument("--target-distance-mm", type=float, default=15000.0)
        q.add_argument("--start-rail-mm", type=float, default=13000.0)
        q.add_argument("--seed", type=int, default=0)


def _add_interop_commands(sub) -> None:
    """The subcommands export, import, openapi, on the subparsers ``sub``."""
    p = sub.add_parser("export", help="write a recording in another format (docs/interop.md)")
    p.add_argument("format", choices=("mcap",), help="mcap: Foxglove / ROS 2 / Rerun")
    p.add_argument("recording")
    p.add_argument("--out", required=True, help="output file (REC.mcap)")
    p.add_argument("--catalog", help="catalog JSON (default: the recording's)")
    p.add_argument("--camera", help="camera JSON (default: the recording's)")
    p.add_argument("--tracking", action="store_true", help="estimate in tracking mode")
    p.add_argument(
        "--no-estimate",
        dest="estimate",
        action="store_false",
        help="frames and reference poses only, no pipeline run",
    )
    p.add_argument(
        "--no-previews",
        dest="previews",
        action="store_false",
        help="leave out the viewer images (/tof/gray_preview, /tof/distance_preview): "
        "a smaller file",
    )
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p = sub.add_parser("import", help="make a recording from another format (docs/interop.md)")
    p.add_argument("format", choices=("mcap",))
    p.add_argument("file", help="input file (REC.mcap)")
    p.add_argument("--out", required=True, help="output recording (REC.h5)")
    p.add_argument("--gray-topic", help=f"gray image topic (default {GRAY_TOPIC})")
    p.add_argument("--distance-topic", help=f"distance image topic (default {DISTANCE_TOPIC})")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p = sub.add_parser("openapi", help="write the server's OpenAPI document (JSON)")
    p.add_argument("--out", required=True)


def _add_batch_commands(sub) -> None:
    """The subcommands study, reprocess, compare, warm-up, on the subparsers ``sub``."""
    p = sub.add_parser(
        "study",
        help="Monte-Carlo accuracy study over a grid of cells, on Dask (docs/scaleout.md)",
    )
    p.add_argument("spec", nargs="?", help="study spec JSON (tofpose study --example prints one)")
    p.add_argument("--out", help="study directory (created; a run of the same spec resumes)")
    p.add_argument("--example", action="store_true", help="print a small example spec and exit")
    _cluster_arguments(p)
    p = sub.add_parser(
        "reprocess",
        help="re-run the pipeline over recordings in chunks on Dask; CSVs as estimate's",
    )
    p.add_argument("recordings", nargs="+", metavar="REC.h5")
    p.add_argument("--out", required=True, help="output directory: <recording>.csv each")
    p.add_argument("--camera", help="camera JSON (default: each recording's)")
    p.add_argument("--catalog", help="catalog JSON (default: each recording's)")
    p.add_argument("--tracking", action="store_true", help="the pipeline's tracking mode")
    p.add_argument("--filter", action="store_true", help="add the relative-state filter's columns")
    p.add_argument("--chunk-frames", type=int, default=512, help="frames per task (default 512)")
    _cluster_arguments(p)
    p = sub.add_parser(
        "compare", help="compare two runs of estimate/reprocess: per-frame pose differences"
    )
    p.add_argument("run_a", help="a CSV, or a reprocess directory")
    p.add_argument("run_b", help="a CSV, or a reprocess directory")
    p.add_argument("--out", required=True, help="output directory (compare.csv/json/png)")
    sub.add_parser(
        "warm-up",
        help="compile the pipeline's kernels into numba's cache (once after installing)",
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``tofpose`` command line: every subcommand and its options."""
    ap = argparse.ArgumentParser(prog="tofpose", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    for add in (
        _add_measurement_commands,
        _add_simulation_commands,
        _add_server_commands,
        _add_interop_commands,
        _add_batch_commands,
    ):
        add(sub)
    return ap


def _run_outside_the_library(args) -> int | None:
    """The subcommands that run outside the library's error handling (the Dask ones,
    the kernel warm-up, the server's and the emulators'); None for the others."""
    if args.cmd == "study":
        return study(args)
    if args.cmd == "reprocess":
        return reprocess(args)
    if args.cmd == "compare":
        return compare(args)
    if args.cmd == "warm-up":
        from tofpose.core.compiled import kernel_cache_dir, prune_stale_kernel_caches
        from tofpose.warmup import warm_up

        print(f"pipeline kernels ready in {warm_up():.1f} s ({kernel_cache_dir()})")
        for old in prune_stale_kernel_caches():
            print(f"removed the stale kernel cache {old}")
        return 0
    if args.cmd == "openapi":
        from backend import main as server_main

        return server_main.write_openapi(args.out)
    if args.cmd == "emulate":
        from backend.emulators import cli as emulators  # lazy, like serve

        return emulators.run(vars(args))
    if args.cmd in ("serve", "report", "keys", "record"):
        from backend import main as server_main  # lazy: the library does not need the server

        opts = vars(args)
        cmd = opts.pop("cmd")
        if cmd == "keys":
            return server_main.keys(opts)  # backend/keys_cli.py
        if cmd == "record":
            return server_main.record(opts)  # backend/record_cli.py
        return server_main.serve(opts) if cmd == "serve" else server_main.report(opts)
    return None


def main(argv: list[str] | None = None) -> int:
    single_threaded_blas()  # tofpose.core.threads: idle BLAS threads would burn a core
    args = build_parser().parse_args(argv)
    code = _run_outside_the_library(args)
    if code is not None:
        return code
    try:
        if args.cmd == "estimate":
            s = estimate(
                args.recording,
                args.out,
                args.catalog,
                args.camera,
                tracking=args.tracking,
                filter_state=args.filter,
            )
            print(f"{s['ok']}/{s['frames']} frames with a pose -> {args.out}")
        elif args.cmd == "export":
            print(export_file(args))
        elif args.cmd == "import":
            print(import_file(args))
        elif args.cmd == "calibrate-covariance":
            print(
                calibrate_covariance(
                    args.recording, args.out, args.camera, args.reference, args.knots_mm
                )
            )
        elif args.cmd == "calibrate-range":
            print(calibrate_range(args.recording, args.out, args.reference, args.modulation_mhz))
        elif args.cmd == "simulate":
            if args.frames < 1:
                raise SystemExit("tofpose: --frames must be >= 1")
            simulate(args.scenario, args.frames, args.out, args.seed, args.catalog)
            print(f"wrote {args.frames} frames -> {args.out}")
        elif args.cmd == "render":
            for path in render_pngs(args.scenario, args.out_prefix, args.seed):
                print(path)
        elif args.cmd == "demo":
            return demo(args.frames)
    except (RecordingError, ValueError) as exc:
        print(f"tofpose: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
