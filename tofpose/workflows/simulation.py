"""``tofpose simulate``, ``render`` and ``demo`` as functions."""

from __future__ import annotations

import csv
import sys
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.depth import z_from_radial
from tofpose.core.geometry import facing_euler_deg, rotation_angle_deg
from tofpose.io.camera_file import camera_from_arg, catalog_from_arg
from tofpose.io.recording import RecordingWriter, open_recording
from tofpose.workflows.measurement import estimate


def simulate(
    scenario_name: str,
    n_frames: int,
    out: str,
    seed: int,
    catalog_path: str | None,
    progress: bool = True,
    camera_arg: str | None = None,
) -> None:
    """Write a simulated recording of a scenario with its truths. ``camera_arg``: a
    camera profile's name or a camera JSON (default: the TOFcam-660, ``CameraModel()``);
    a z-depth camera's recording holds z depth, as the device would give it (the
    recording reader converts it back to radial)."""
    from tofpose.sim.scenarios import get_scenario, run_scenario

    scenario = get_scenario(scenario_name)
    catalog = catalog_from_arg(catalog_path) if catalog_path else paper_target()
    camera = camera_from_arg(camera_arg) if camera_arg else CameraModel()
    with RecordingWriter(out, camera, catalog, with_truth=True, with_reference=True) as w:
        for bf in tqdm(
            run_scenario(
                scenario,
                n_frames,
                seed=seed,
                catalog=catalog,
                camera=camera if camera_arg else None,
            ),
            total=n_frames,
            desc=f"simulate {scenario_name}",
            unit="frame",
            disable=not progress,
            file=sys.stderr,
        ):
            distance_mm = bf.frame.distance_mm  # radial, as rendered
            if camera.distance_kind == "z":
                distance_mm = z_from_radial(distance_mm, camera)
            w.append(
                bf.frame.gray,
                distance_mm,
                bf.time_s,
                bf.T_true.R,  # /truth: the pose the simulator rendered
                bf.T_true.t_mm,
                lab_R_camera_target=bf.T_lab_truth.R,  # /lab_truth: encoders + nominal
                lab_t_camera_target_mm=bf.T_lab_truth.t_mm,
            )


def render_pngs(
    scenario_name: str, prefix: str, seed: int, camera_arg: str | None = None
) -> list[str]:
    """Write PREFIX-gray.png and PREFIX-distance.png of a scenario's first frame;
    ``camera_arg``: through this camera profile or camera JSON (default: TOFcam-660)."""
    import cv2

    from tofpose.sim.scenarios import get_scenario, run_scenario

    camera = camera_from_arg(camera_arg) if camera_arg else None
    bf = next(run_scenario(get_scenario(scenario_name), 1, seed=seed, camera=camera))
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
            truth_R, truth_t_mm = r.truth_R, r.truth_t_mm
            if truth_R is None or truth_t_mm is None:
                raise RuntimeError(f"{rec}: the simulated recording has no /truth")
            errs = []
            for i in range(0, r.n_frames, max(1, r.n_frames // 24)):
                row = rows[i]
                R_t, t_t = truth_R[i], truth_t_mm[i]
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
