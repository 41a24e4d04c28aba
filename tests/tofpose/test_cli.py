import csv

import pytest

from tofpose.cli import main
from tofpose.io.pose_csv import CSV_COLUMNS


def test_simulate_then_estimate_writes_the_documented_csv(tmp_path, capsys):
    rec, out = tmp_path / "r.h5", tmp_path / "poses.csv"
    assert (
        main(["simulate", "--scenario", "stability-697", "--frames", "4", "--out", str(rec)]) == 0
    )
    assert main(["estimate", str(rec), "--out", str(out)]) == 0
    rows = list(csv.reader(out.open()))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert len(rows) == 5
    body = [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]
    assert all(r["ok"] == "1" for r in body)
    assert all(abs(float(r["z_mm"]) - 697) < 10 for r in body)
    # attitude relative to the facing reference: face-on reads ~0, not +-180
    assert all(abs(float(r[k])) < 2.0 for r in body for k in ("pitch_deg", "yaw_deg", "roll_deg"))
    assert "4/4 frames with a pose" in capsys.readouterr().out
    # tracking mode gives the same poses within their sigma on this static recording
    tracked = tmp_path / "tracked.csv"
    assert main(["estimate", str(rec), "--out", str(tracked), "--tracking"]) == 0
    rows_t = [dict(zip(rows[0], r, strict=True)) for r in list(csv.reader(tracked.open()))[1:]]
    for a, b in zip(body, rows_t, strict=True):
        assert abs(float(a["z_mm"]) - float(b["z_mm"])) < float(a["sigma_z_mm"])
    # the 1-sigma columns come after the original ones (old readers keep working)
    assert CSV_COLUMNS[:15][-1] == "residual_mm" and CSV_COLUMNS[15] == "sigma_x_mm"
    assert all(0 < float(r["sigma_z_mm"]) < 2.0 for r in body)
    assert all(0 < float(r["sigma_ry_deg"]) < 1.0 for r in body)


def test_failed_frames_have_empty_pose_cells(tmp_path):
    import numpy as np

    from tofpose.core.camera import CameraModel
    from tofpose.core.catalog import paper_target
    from tofpose.io.recording import RecordingWriter

    rec, out = tmp_path / "dark.h5", tmp_path / "p.csv"
    with RecordingWriter(rec, CameraModel(), paper_target()) as w:
        w.append(np.zeros((240, 320), np.uint16), np.full((240, 320), np.nan, np.float32), 0.0)
    assert main(["estimate", str(rec), "--out", str(out)]) == 0
    row = list(csv.DictReader(out.open()))[0]
    assert row["ok"] == "0" and row["x_mm"] == "" and row["residual_mm"] == ""
    assert row["sigma_rz_deg"] == ""


def test_estimate_with_the_filter_adds_rate_and_velocity_of_a_static_target(tmp_path):
    """``estimate --filter``: the relative-state filter's columns after the pose's; the
    stability recording's target does not move, so the rates and velocities it reports
    are zero within their own 3 sigma once it has seen a few frames."""
    from tofpose.io.pose_csv import FILTER_COLUMNS

    rec, out = tmp_path / "r.h5", tmp_path / "poses.csv"
    assert (
        main(["simulate", "--scenario", "stability-697", "--frames", "12", "--out", str(rec)]) == 0
    )
    assert main(["estimate", str(rec), "--out", str(out), "--filter"]) == 0
    rows = list(csv.reader(out.open()))
    assert tuple(rows[0]) == CSV_COLUMNS + FILTER_COLUMNS
    body = [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]
    assert body[0]["filter_status"] == "initialised"
    assert {r["filter_status"] for r in body[1:]} == {"updated"}
    for r in body[4:]:
        for axis in "xyz":
            assert abs(float(r[f"rate_{axis}_deg_s"])) < 3 * float(r[f"sigma_rate_{axis}_deg_s"])
            assert abs(float(r[f"vel_{axis}_mm_s"])) < 3 * float(r[f"sigma_vel_{axis}_mm_s"])
    # well below the 30 deg/s it starts from: the poses told it the rate
    assert float(body[-1]["sigma_rate_y_deg_s"]) < 3.0


def test_estimate_with_the_filter_reads_a_tumbles_rate_within_ten_percent(tmp_path):
    """A target tumbling at 6 deg/s about an axis near the line of sight, 5 m away, 10
    poses a second: its markers' images move ~0.2 px a frame, under persistence's motion
    gate, so frames combined over time make each pose lag the tumble by a frame or so and
    the rate read from them is off by ~15 %. ``estimate --filter`` measures each pose on
    its own frame: the rate is within 10 % of the truth at every frame, the first
    included (smoothed over the whole recording); with ``--causal`` (the live loop's
    view) it starts from nothing and is within 10 % after 3 s."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from tofpose.core.camera import CameraModel
    from tofpose.core.catalog import paper_target
    from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
    from tofpose.io.recording import RecordingWriter
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel, render_frame
    from tofpose.sim.scene import TargetScene

    cam, cat = CameraModel(), paper_target()
    rng = np.random.default_rng(5)
    axis = np.array([-0.04, -0.61, 0.79])
    axis /= np.linalg.norm(axis)
    rate = np.radians(6.0)
    R0 = rotation_from_euler_deg(4.0, -6.0, 3.0) @ R_FACING
    centre = np.array([80.0, -40.0, 5000.0])
    rec, out = tmp_path / "tumble.h5", tmp_path / "poses.csv"
    with RecordingWriter(rec, cam, cat) as w:
        for k in range(70):
            t = k / 10
            R = Rotation.from_rotvec(axis * rate * t).as_matrix() @ R0
            T = RigidTransform(R, centre - R @ cat.positions_mm.mean(axis=0))
            f = render_frame(cam, TargetScene(cat), T, SensorModel(), rng)
            w.append(f.gray, f.distance_mm, t)

    def rate_errors(*flags: str) -> np.ndarray:
        assert main(["estimate", str(rec), "--out", str(out), "--filter", *flags]) == 0
        rows = list(csv.DictReader(out.open()))
        assert len(rows) == 70 and all(r["ok"] == "1" for r in rows)
        measured = np.array([[float(r[f"rate_{a}_deg_s"]) for a in "xyz"] for r in rows])
        return np.linalg.norm(measured - np.degrees(axis * rate), axis=1)

    smoothed, causal = rate_errors(), rate_errors("--causal")
    assert np.sqrt(np.mean(smoothed**2)) < 0.10 * np.degrees(rate)
    assert smoothed[:5].max() < 0.10 * np.degrees(rate)
    assert causal[0] > 0.5 * np.degrees(rate)  # the live view has no rate at its first pose
    assert np.sqrt(np.mean(causal[30:] ** 2)) < 0.10 * np.degrees(rate)


def test_calibrate_range_writes_a_camera_the_estimate_uses(tmp_path, capsys):
    """simulate a realistic sweep, fit its range correction, estimate with it: the
    correction is stored with the camera and applied: errors against /truth shrink at
    2.5-6.5 m, where the systematic errors dominate and the sweep's reflectors gave the
    fit its samples (beyond ~6 m they are a pixel or two, all edge, and the model would
    extrapolate)."""
    import numpy as np

    from tofpose.io.camera_file import load_camera
    from tofpose.io.recording import open_recording

    rec, cam, raw_csv, cal_csv = (tmp_path / n for n in ("r.h5", "c.json", "a.csv", "b.csv"))
    assert main(["simulate", "--scenario", "realistic", "--frames", "72", "--out", str(rec)]) == 0
    assert main(["calibrate-range", str(rec), "--out", str(cam)]) == 0
    printed = capsys.readouterr().out
    assert "cyclic amplitudes" in printed
    camera, corr, _ = load_camera(cam.read_text())
    assert corr is not None and camera.width == 320
    near, far = corr.calibrated_span_mm  # stored with the camera and printed
    assert f"calibrated span {near:.0f}-{far:.0f} mm" in printed and near < far
    # the centroid pose with the configured priors: what the correction alone does
    centroid = ["--no-pixel-fit", "--no-learn-range-bias"]
    assert main(["estimate", str(rec), "--out", str(raw_csv), *centroid]) == 0
    assert main(["estimate", str(rec), "--camera", str(cam), "--out", str(cal_csv), *centroid]) == 0
    # estimate's default on the uncalibrated recording: the pixel fit, with the range
    # offsets' mean and spread learned over the recording
    default_csv = tmp_path / "d.csv"
    assert main(["estimate", str(rec), "--out", str(default_csv)]) == 0
    with open_recording(rec) as r:
        true_z = r.truth_t_mm[:, 2]
    errs = {}
    for name, path in (("raw", raw_csv), ("cal", cal_csv), ("default", default_csv)):
        rows = list(csv.DictReader(path.open()))
        far = [
            abs(float(x["z_mm"]) - true_z[i])
            for i, x in enumerate(rows)
            if x["ok"] == "1" and 2500 < true_z[i] < 6500
        ]
        errs[name] = float(np.median(far))
    assert errs["cal"] < 0.5 * errs["raw"], errs
    assert errs["default"] < 0.5 * errs["raw"], errs


def test_calibrate_covariance_writes_a_camera_whose_sigmas_the_estimate_reports(tmp_path, capsys):
    """calibrate-covariance fits the factor per range against /truth and stores it with
    the camera; estimate with that camera reports the same poses with the 1-sigma
    columns scaled by the square root of the factor at each pose's distance."""
    import json

    import numpy as np

    from tofpose.io.camera_file import load_camera

    rec, cam, raw_csv, cal_csv = (tmp_path / n for n in ("r.h5", "c.json", "a.csv", "b.csv"))
    assert main(["simulate", "--scenario", "range-sweep", "--frames", "54", "--out", str(rec)]) == 0
    assert main(["calibrate-covariance", str(rec), "--out", str(cam)]) == 0
    printed = capsys.readouterr().out
    assert "frames with a pose" in printed and "mean NEES" in printed
    _, _, scale = load_camera(cam.read_text())
    assert scale is not None and json.loads(cam.read_text())["covariance_scale"]
    # the simulator's errors are smaller than the model's floors claim: factors below 1
    assert all(0.01 < f < 1.0 for f in scale.factors), scale
    # the centroid pose's covariance, with the configured priors (what the scale was
    # fitted on: a camera with a scale keeps them, and the pixel fit's covariance is the
    # sensor model's own, not scaled)
    centroid = ["--no-pixel-fit", "--no-learn-range-bias"]
    assert main(["estimate", str(rec), "--out", str(raw_csv), *centroid]) == 0
    assert (
        main(["estimate", str(rec), "--camera", str(cam), "--out", str(cal_csv), "--no-pixel-fit"])
        == 0
    )
    assert "range bias learned" not in capsys.readouterr().out
    raw, cal = (list(csv.DictReader(p.open())) for p in (raw_csv, cal_csv))
    n_ok = 0
    for a, b in zip(raw, cal, strict=True):
        assert (a["ok"], a["x_mm"], a["z_mm"], a["yaw_deg"]) == (
            b["ok"],
            b["x_mm"],
            b["z_mm"],
            b["yaw_deg"],
        )
        if a["ok"] == "1":
            n_ok += 1
            t = np.array([float(a[k]) for k in ("x_mm", "y_mm", "z_mm")])
            root = np.sqrt(scale.factor_at(float(np.linalg.norm(t))))
            for k in ("sigma_z_mm", "sigma_ry_deg"):
                assert float(b[k]) == pytest.approx(float(a[k]) * root, rel=2e-3, abs=2e-4)
    assert n_ok >= 20
    # a knot the recording has no frames near is refused, by name
    assert (
        main(["calibrate-covariance", str(rec), "--out", str(cam), "--knots-mm", "2000,1e9"]) == 2
    )
    assert "too few at 1000000000 mm (0)" in capsys.readouterr().err


def test_bad_inputs_exit_with_a_message(tmp_path, capsys):
    assert main(["estimate", str(tmp_path / "nope.h5"), "--out", str(tmp_path / "o.csv")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert (
        main(["simulate", "--scenario", "bogus", "--frames", "1", "--out", str(tmp_path / "x.h5")])
        == 2
    )
    assert "unknown scenario" in capsys.readouterr().err
    bad_cat = tmp_path / "cat.json"
    bad_cat.write_text(
        '{"name": "x", "reflectors": [{"id": 1, "position_mm": [0,0,0], "diameter_mm": 5},'
        '{"id": 1, "position_mm": [9,0,0], "diameter_mm": 5},'
        '{"id": 2, "position_mm": [0,9,0], "diameter_mm": 5}]}'
    )

    def simulate_with(catalog):
        out = str(tmp_path / "y.h5")
        argv = ["simulate", "--scenario", "clutter", "--frames", "1", "--out", out]
        return main([*argv, "--catalog", str(catalog)])

    with pytest.raises(SystemExit):
        simulate_with(tmp_path / "missing.json")
    assert simulate_with(bad_cat) == 2
    assert "duplicate reflector ids" in capsys.readouterr().err


def test_simulated_truth_is_what_was_rendered_and_the_reference_is_apart(tmp_path):
    """/truth is the rendered pose; /reference (encoders + nominal geometry) differs from
    it by the simulated mount and placement errors, and the pipeline agrees with /truth."""
    import h5py
    import numpy as np

    from tofpose.io.recording import open_recording
    from tofpose.sim.scenarios import get_scenario, run_scenario

    rec = tmp_path / "r.h5"
    assert (
        main(["simulate", "--scenario", "stability-697", "--frames", "3", "--out", str(rec)]) == 0
    )
    with h5py.File(rec) as f:
        assert "truth" in f and "reference" in f and "lab_truth" not in f
    expected = list(run_scenario(get_scenario("stability-697"), 3, seed=0))
    with open_recording(rec) as r:
        for i, bf in enumerate(expected):
            np.testing.assert_allclose(r.truth_R[i], bf.T_true.R, atol=1e-12)
            np.testing.assert_allclose(r.truth_t_mm[i], bf.T_true.t_mm, atol=1e-9)
            np.testing.assert_allclose(r.reference_t_mm[i], bf.T_lab_truth.t_mm, atol=1e-9)
        lab_off = np.linalg.norm(r.reference_t_mm - r.truth_t_mm, axis=1)
        assert np.all(lab_off > 0.5)  # the mount error the lab does not know
    out = tmp_path / "poses.csv"
    assert main(["estimate", str(rec), "--out", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    with open_recording(rec) as r:
        for i, row in enumerate(rows):
            est = np.array([float(row[k]) for k in ("x_mm", "y_mm", "z_mm")])
            assert np.linalg.norm(est - r.truth_t_mm[i]) < 2.0 < lab_off[i] + 2.0


def test_the_library_commands_run_without_the_server_package(tmp_path):
    """With ``backend`` and the web stack unimportable (a finder refuses them), the
    command line still parses, leaves out the server's commands and simulates and
    estimates a recording; ``serve`` is then an unknown command."""
    import subprocess
    import sys

    code = f"""
import sys
class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("backend", "fastapi", "sqlalchemy", "uvicorn", "viser"):
            raise ImportError("refused: " + name)
sys.meta_path.insert(0, Refuse())
from tofpose.cli import build_parser, main
assert main(["simulate", "--scenario", "attitude-grid", "--frames", "2",
             "--out", r"{tmp_path / "rec.h5"}"]) == 0
assert main(["estimate", r"{tmp_path / "rec.h5"}", "--out", r"{tmp_path / "p.csv"}"]) == 0
assert not any(m.split(".")[0] == "backend" for m in sys.modules)
try:
    build_parser().parse_args(["serve"])
except SystemExit as exc:
    print("serve refused", exc.code)
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=900, check=True
    )
    assert "serve refused 2" in out.stdout, out.stdout + out.stderr
    assert (tmp_path / "p.csv").read_text().count("\n") == 3  # header and two frames


def test_version_is_the_installed_distributions(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"tofpose {version('tofpose')}"


def test_the_server_commands_come_from_the_entry_point_group():
    from tofpose.cli import registered_commands

    commands = registered_commands()
    assert {"serve", "report", "keys", "record", "emulate", "openapi"} <= set(commands)
    assert all(c.name == name for name, c in commands.items())


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--scenario", "attitude-grid", "--frames", "2", "--out", "{d}/none/x.h5"],
        ["estimate", "{d}/r.h5", "--out", "{d}/none/p.csv"],
        ["render", "--out-prefix", "{d}/none/frame"],
        ["export", "mcap", "{d}/r.h5", "--out", "{d}/none/r.mcap"],
    ],
)
def test_a_missing_output_directory_is_named_before_any_work(tmp_path, capsys, argv):
    code = main([a.format(d=tmp_path) for a in argv])
    assert code == 2
    err = capsys.readouterr().err
    assert f"the output's directory '{tmp_path / 'none'}' does not exist" in err
    assert not (tmp_path / "none").exists()


def test_simulate_through_a_z_depth_profile_then_estimate(tmp_path, capsys):
    """``simulate --camera azure-kinect-nfov`` writes the device's frames (640 x 576, z
    depth in mm, 16-bit counts); ``estimate`` reads them as radial and gets the pose."""
    import h5py
    import numpy as np

    from tofpose.core.depth import z_from_radial
    from tofpose.io.recording import open_recording

    rec, out = tmp_path / "k.h5", tmp_path / "poses.csv"
    argv = ["simulate", "--scenario", "stability-697", "--frames", "3", "--out", str(rec)]
    assert main([*argv, "--camera", "azure-kinect-nfov"]) == 0
    with h5py.File(rec, "r") as f:
        assert f["camera"].attrs["distance_kind"] == "z"
        assert f["frames/distance_mm"].shape == (3, 576, 640)
        stored_z = f["frames/distance_mm"][0]
    with open_recording(rec) as r:
        radial = r.frame(0)[1]
        np.testing.assert_allclose(z_from_radial(radial, r.camera), stored_z, rtol=1e-6)
        assert r.frame(0)[0].max() > 4095  # the 16-bit count scale
        truth_t = r.truth_t_mm
    assert main(["estimate", str(rec), "--out", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["ok"] for r in rows] == ["1", "1", "1"]
    for row, t in zip(rows, truth_t, strict=True):
        err = np.array([float(row[k]) for k in ("x_mm", "y_mm", "z_mm")]) - t
        sigma = np.array([float(row[k]) for k in ("sigma_x_mm", "sigma_y_mm", "sigma_z_mm")])
        assert np.all(np.abs(err) < 4 * sigma)
    capsys.readouterr()
    with pytest.raises(SystemExit, match="azure-kinect-nfov, hololens2-ahat, tofcam660"):
        main([*argv, "--camera", "kinect"])


def test_render_through_a_profile_writes_its_image_size(tmp_path, capsys):
    import cv2

    prefix = str(tmp_path / "ahat")
    argv = ["render", "--scenario", "stability-697", "--out-prefix", prefix]
    assert main([*argv, "--camera", "hololens2-ahat"]) == 0
    for kind in ("gray", "distance"):
        assert cv2.imread(f"{prefix}-{kind}.png").shape[:2] == (1024, 1024)  # 512 x 512, x2


def test_a_camera_that_replaces_the_recordings_intrinsics_is_named(tmp_path, capsys):
    """``estimate --camera`` measures with that camera's intrinsics: when they are not the
    recording's, it says so (a profile's nominal focal length on another unit's frames
    moves the pose); the recording's own intrinsics pass without a word."""
    import json

    from tofpose.core.camera import CameraModel

    rec, out = tmp_path / "r.h5", tmp_path / "poses.csv"
    assert (
        main(["simulate", "--scenario", "stability-697", "--frames", "1", "--out", str(rec)]) == 0
    )
    same, other = tmp_path / "same.json", tmp_path / "other.json"
    same.write_text(CameraModel().to_json())
    other.write_text(json.dumps({**CameraModel().to_dict(), "fx": 330.0}))
    capsys.readouterr()
    assert main(["estimate", str(rec), "--out", str(out), "--camera", str(same)]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["estimate", str(rec), "--out", str(out), "--camera", str(other)]) == 0
    err = capsys.readouterr().err
    assert "replaces the recording's intrinsics (fx 325, fy 325" in err and "(fx 330," in err


@pytest.mark.parametrize("reference", ["truth", "reference", "lab_truth"])
def test_calibrate_range_names_the_pose_group_a_recording_lacks(tmp_path, reference):
    """``--reference`` takes truth (the rendered pose), reference (the lab's) or the
    older name lab_truth; a recording without it is refused naming the group."""
    import numpy as np

    from tofpose.core.camera import CameraModel
    from tofpose.io.recording import RecordingWriter

    rec = tmp_path / "frames-only.h5"
    with RecordingWriter(rec, CameraModel()) as w:
        w.append(np.zeros((240, 320), np.uint16), np.full((240, 320), 1e3, np.float32), 0.0)
    with pytest.raises(SystemExit, match=f"has no /{reference}: nothing to calibrate against"):
        main(
            [
                "calibrate-range",
                str(rec),
                "--out",
                str(tmp_path / "c.json"),
                "--reference",
                reference,
            ]
        )
