"""``--camera``: a shipped profile's name or a camera JSON file; the range bias learned
over a recording (``learned_range_bias``)."""

import json

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import load_profile, profile_text
from tofpose.io.camera_file import camera_from_arg, load_camera, read_camera_text


def test_a_profile_name_or_a_camera_json_path(tmp_path):
    assert camera_from_arg("hololens2-ahat") == load_profile("hololens2-ahat")
    path = tmp_path / "cam.json"
    path.write_text(CameraModel(fx=300.0, name="mine").to_json())
    assert camera_from_arg(str(path)) == CameraModel(fx=300.0, name="mine")
    # a profile with the calibrations' additions still reads as one
    doc = {**json.loads(profile_text("tofcam660")), "range_correction": None}
    path.write_text(json.dumps(doc))
    assert load_camera(path.read_text())[0] == CameraModel()


def test_neither_a_file_nor_a_profile_lists_the_profiles(tmp_path):
    with pytest.raises(
        SystemExit,
        match="neither a camera JSON file nor a camera profile "
        r"\(azure-kinect-nfov, hololens2-ahat, tofcam660\)",
    ):
        read_camera_text("kinect")
    with pytest.raises(SystemExit, match="cannot read camera .*missing.json"):
        read_camera_text(str(tmp_path / "missing.json"))


@pytest.mark.parametrize("key", ["distance_kind", "fx", "count_scale"])
def test_a_profile_file_missing_a_field_names_it(tmp_path, key):
    doc = json.loads(profile_text("azure-kinect-nfov"))
    del doc[key]
    path = tmp_path / "my-kinect.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(SystemExit, match=f"camera profile azure-kinect-nfov is missing {key}$"):
        camera_from_arg(str(path))


def test_a_camera_file_that_is_not_a_camera_is_named(tmp_path):
    path = tmp_path / "cam.json"
    for text, message in (("{", "not valid JSON"), ("[]", "must be an object")):
        path.write_text(text)
        with pytest.raises(SystemExit, match=message):
            camera_from_arg(str(path))


def test_a_catalog_argument_is_a_built_in_name_or_a_json_file(tmp_path):
    from tofpose.core.catalog import paper_target
    from tofpose.io.camera_file import catalog_from_arg

    assert catalog_from_arg("paper-target") == paper_target()
    path = tmp_path / "cat.json"
    path.write_text(paper_target().to_json())
    assert catalog_from_arg(str(path)) == paper_target()
    with pytest.raises(SystemExit, match="cannot read catalog"):
        catalog_from_arg(str(tmp_path / "missing.json"))
    path.write_text('{"name": "x", "reflectors": []}')
    with pytest.raises(ValueError, match="at least 3 reflectors"):
        catalog_from_arg(str(path))


def _far_recording(path, n_frames: int, offset_mm: float = 0.0, seed: int = 12):
    """A recording of the paper target at 3-5 m (facing within 5 deg, off-centre up
    to 150 mm), rendered by an ideal sensor whose ranges read ``offset_mm`` long, with
    its truth; returns the true translations (n, 3)."""
    from tofpose.core.catalog import paper_target
    from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
    from tofpose.io.recording import RecordingWriter
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel, render_frame
    from tofpose.sim.scene import TargetScene

    rng = np.random.default_rng(seed)
    cam, truth = CameraModel(), []
    with RecordingWriter(path, cam, paper_target(), with_truth=True) as w:
        for i in range(n_frames):
            T = RigidTransform(
                rotation_from_euler_deg(*rng.uniform(-5, 5, 3)) @ R_FACING,
                np.array([*rng.uniform(-150, 150, 2), rng.uniform(3000, 5000)]),
            )
            f = render_frame(cam, TargetScene(), T, SensorModel(), rng)
            w.append(f.gray, f.distance_mm + offset_mm, 0.1 * i, T.R, T.t_mm)
            truth.append(T.t_mm)
    return np.array(truth)


def _learned(rec):
    """``learned_range_bias`` over the recording ``rec``, with the pixel fit (estimate's
    default)."""
    from tofpose.io.camera_file import learned_range_bias
    from tofpose.io.recording import open_recording

    with open_recording(str(rec)) as r:
        return learned_range_bias(r, str(rec), None, None, pixel_fit=True, progress=False)


def _z_errors(rec, truth, out, *flags):
    """``tofpose estimate`` of ``rec`` with ``flags`` into ``out``: every frame ok, its z
    errors against ``truth`` (n, 3) and its z sigmas, mm."""
    import csv

    from tofpose.cli import main

    assert main(["estimate", str(rec), "--out", str(out), *flags]) == 0
    rows = list(csv.DictReader(out.open()))
    assert all(row["ok"] == "1" for row in rows)
    z = np.array([float(row["z_mm"]) for row in rows]) - truth[:, 2]
    return z, np.array([float(row["sigma_z_mm"]) for row in rows])


def _rms(e):
    return float(np.sqrt(np.mean(e**2)))


def test_a_calibrated_cameras_range_bias_is_learned_near_zero_and_its_poses_follow_the_ranges(
    tmp_path, capsys
):
    """A camera without range offset: the frames' offsets spread ~0, so ``estimate``
    measures every frame with a prior far below the uncalibrated 15 mm and the
    position along the line of sight follows the ranges instead of each frame's image
    scale: its RMS error well below the run that does not learn, its sigma still
    covering it."""
    rec = tmp_path / "far.h5"
    truth = _far_recording(rec, 32)
    learned = _learned(rec)
    assert learned is not None and learned.n_frames >= 28
    assert learned.sigma_mm < 5.0
    z_learned, sigma_learned = _z_errors(rec, truth, tmp_path / "learned.csv")
    assert "range bias learned over" in capsys.readouterr().out
    z_fixed, _ = _z_errors(rec, truth, tmp_path / "fixed.csv", "--no-learn-range-bias")
    assert "range bias learned" not in capsys.readouterr().out
    assert _rms(z_learned) < 0.8 * _rms(z_fixed)
    assert _rms(z_learned / sigma_learned) < 1.5


def test_an_offset_cameras_range_offset_is_learned_and_taken_out(tmp_path):
    """Ranges 12 mm long on every frame: the learned mean reads the offset and the
    spread about it stays small, so estimate takes it out of every frame: the position
    along the line of sight is then as good as the calibrated camera's, where the
    configured prior (N(0, 15^2)) leaves each frame to find it in its image scale."""
    rec = tmp_path / "offset.h5"
    truth = _far_recording(rec, 32, offset_mm=12.0, seed=13)
    learned = _learned(rec)
    assert learned is not None
    assert learned.mean_mm == pytest.approx(12.0, abs=3 * learned.mean_se_mm + 0.5)
    assert learned.sigma_mm < 6.0
    z_learned, _ = _z_errors(rec, truth, tmp_path / "learned.csv")
    z_fixed, _ = _z_errors(rec, truth, tmp_path / "fixed.csv", "--no-learn-range-bias")
    assert _rms(z_learned) < 0.6 * _rms(z_fixed)


def test_the_pixel_fit_is_on_unless_the_camera_carries_a_covariance_scale(tmp_path):
    from tofpose.calibration.covariance import CovarianceScale
    from tofpose.io.camera_file import resolve_pixel_fit

    plain, scaled = tmp_path / "plain.json", tmp_path / "scaled.json"
    plain.write_text(CameraModel().to_json())
    scale = CovarianceScale((1000.0,), (0.5,)).to_dict()
    scaled.write_text(json.dumps({**CameraModel().to_dict(), "covariance_scale": scale}))
    assert resolve_pixel_fit(None, None) is True
    assert resolve_pixel_fit(None, str(plain)) is True
    assert resolve_pixel_fit(None, str(scaled)) is False
    assert resolve_pixel_fit(True, str(scaled)) is True
    assert resolve_pixel_fit(False, None) is False
