"""bench/foreign.py: its metrics on poses with errors built on purpose, and an end-to-end
run on a tiny recording of our simulator (one with its true /truth, one whose /truth of
one pose is turned by 3 deg, which the harness must call wrong and confidently so)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from bench import foreign
from bench._foreign_metrics import (
    CHI2_6_3SIGMA,
    FrameOutcome,
    TrueImages,
    common_scale_error_px,
    common_scale_excess_px,
    mahalanobis2,
    pose_error,
    position_tolerance_mm,
    range_bins,
    summarise,
    true_correspondences,
)
from tests.conftest import facing_pose, render
from tofpose.calibration.covariance import pose_nees
from tofpose.cli import main as tofpose_main
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.io.recording import RecordingWriter


def _rot(axis: str, deg: float) -> np.ndarray:
    return Rotation.from_euler(axis, deg, degrees=True).as_matrix()


def _outcome(range_mm, att_deg=0.0, pos_mm=0.0, sigma_deg=0.5, sigma_mm=5.0, ok=True):
    """A frame whose pose is off by ``att_deg`` about x and ``pos_mm`` along z, with a
    diagonal covariance of those sigmas."""
    if not ok:
        return FrameOutcome(0, range_mm, False, "no blobs")
    e = np.array([math.radians(att_deg), 0, 0, 0, 0, pos_mm])
    cov = np.diag([math.radians(sigma_deg) ** 2] * 3 + [sigma_mm**2] * 3)
    return FrameOutcome(0, range_mm, True, "", e, cov, 5, 0)


def test_pose_error_and_mahalanobis_follow_the_covariance_convention():
    R_true = _rot("xyz", [10.0, -20.0, 170.0])
    t_true = np.array([100.0, -50.0, 3000.0])
    R_est = _rot("x", 1.5) @ R_true  # left perturbation: 1.5 deg about camera x
    t_est = t_true + [10.0, 0.0, -5.0]
    e = pose_error(R_est, t_est, R_true, t_true)
    np.testing.assert_allclose(e, [math.radians(1.5), 0, 0, 10, 0, -5], atol=1e-12)
    cov = np.diag([math.radians(0.5) ** 2] * 3 + [5.0**2] * 3)
    # (1.5 / 0.5)^2 + (10 / 5)^2 + (5 / 5)^2
    assert mahalanobis2(e, cov) == pytest.approx(9 + 4 + 1)
    # the project's NEES (the covariance calibration's) is the same number, also with
    # correlations between rotation and translation
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    full = A @ A.T + np.diag([1e-5] * 3 + [4.0] * 3)
    assert mahalanobis2(e, full) == pytest.approx(pose_nees(R_est, t_est, full, R_true, t_true))
    assert mahalanobis2(e, np.zeros((6, 6))) == math.inf


def test_three_sigma_threshold_is_the_chi2_6_quantile_at_0_9973():
    assert abs(CHI2_6_3SIGMA - 20.062) < 1e-3
    assert chi2.cdf(CHI2_6_3SIGMA, 6) == pytest.approx(0.9973, abs=1e-4)


def test_success_wrong_and_confidently_wrong_rules():
    assert position_tolerance_mm(3000.0) == 20.0 and position_tolerance_mm(8000.0) == 40.0
    cases = {
        # (range, att deg, pos mm): (success, wrong)
        (3000, 0.9, 15): (True, False),
        (3000, 1.5, 0): (False, False),  # neither: between the two rules
        (3000, 0, 45): (False, False),
        (3000, 2.5, 0): (False, True),
        (3000, 0, 55): (False, True),  # > 2.5 x 20 mm
        (8000, 0, 35): (True, False),  # tolerance 40 mm at 8 m
        (8000, 0, 99): (False, False),
        (8000, 0, 101): (False, True),
    }
    for (r, a, p), (success, wrong) in cases.items():
        o = _outcome(r, a, p)
        assert (o.success, o.wrong) == (success, wrong), (r, a, p)
    # confidently wrong: wrong and d2 beyond 20.06; 2.5 deg against 0.5 deg is d2 = 25
    assert _outcome(3000, 2.5, 0).confidently_wrong
    assert not _outcome(3000, 2.5, 0, sigma_deg=1.0).confidently_wrong  # d2 = 6.25
    assert _outcome(3000, 0.0, 0.0).d2 == 0.0 and not _outcome(3000).beyond_3sigma
    none = _outcome(3000, ok=False)
    assert not (none.success or none.wrong or none.confidently_wrong or none.beyond_3sigma)


def test_summary_of_frames_with_known_errors():
    frames = [
        _outcome(3000, 0.5, 10),  # success, d2 = 1 + 4
        _outcome(3000, 0.3, 2),  # success, d2 = 0.36 + 0.16
        _outcome(3000, 3.0, 0),  # wrong, d2 = 36: confidently
        _outcome(3000, 2.5, 0, sigma_deg=2.5),  # wrong, d2 = 1: honest
        _outcome(3000, ok=False),
    ]
    s = summarise(frames)
    assert s["frames"] == 5 and s["no_pose"] == 1
    assert s["success_pct"] == pytest.approx(40.0)
    assert (s["wrong"], s["confident_wrong"]) == (2, 1)
    assert s["beyond_3sigma_pct"] == pytest.approx(25.0)
    d2 = [5.0, 0.52, 36.0, 1.0]
    assert s["nees_over_6"] == pytest.approx(np.mean(d2) / 6.0)
    assert s["median_attitude_deg"] == pytest.approx(0.4)
    assert s["median_position_mm"] == pytest.approx(6.0)
    z_rx = [0.5 / 0.5, 0.3 / 0.5, 3.0 / 0.5, 2.5 / 2.5]
    z_z = [10 / 5, 2 / 5, 0, 0]
    spread = s["spread_over_sigma"]
    assert spread[0] == pytest.approx(np.sqrt(np.mean(np.square(z_rx))))
    assert spread[5] == pytest.approx(np.sqrt(np.mean(np.square(z_z))))
    assert spread[1] == 0.0 and s["mismatch_frames"] == 0


def test_range_bins_find_the_distinct_ranges():
    idx, labels = range_bins(np.array([3100.0, 4650, 3150, 8200, 4700, 3120]))
    assert labels == ["3.1 m", "4.7 m", "8.2 m"]
    assert idx.tolist() == [0, 1, 0, 2, 1, 0]
    idx, labels = range_bins(np.array([3100.0, 4650, 3950, 8200]), width_m=1.0)
    assert labels == ["3-4 m", "4-5 m", "8-9 m"] and idx.tolist() == [0, 1, 0, 2]


def test_true_correspondences_are_one_to_one_within_the_gates():
    truth = TrueImages(
        point_mm=np.zeros((3, 3)),
        uv_px=np.array([[100.0, 100.0], [110.0, 100.0], [200.0, 50.0]]),
        range_mm=np.array([3000.0, 3000.0, 3100.0]),
        radius_px=np.array([2.0, 2.0, 2.0]),
        in_view=np.array([True, True, False]),
    )
    uv = np.array([[109.0, 101.0], [150.0, 150.0], [100.5, 99.0], [100.2, 100.0], [200, 50]])
    rho = np.array([3010.0, 3000.0, 3000.0, 3500.0, 3100.0])
    # the spurious blob, the one off in range and the one on a reflector out of view
    # get none; the two near reflectors 1 and 0 get theirs
    assert true_correspondences(uv, rho, truth).tolist() == [1, -1, 0, -1, -1]
    # two blobs on one reflector: the nearer one gets it
    two = np.array([[100.5, 100.0], [101.5, 100.0]])
    assert true_correspondences(two, [3000.0, 3000.0], truth).tolist() == [0, -1]


# -- end to end on the simulator -----------------------------------------------------------
POSES = [  # (range mm, pitch, yaw, roll deg, offset mm); three frames each, as the foreign
    (1500.0, 5.0, -8.0, 3.0, (60.0, -40.0)),  # recordings
    (3000.0, -6.0, 4.0, -2.0, (-150.0, 100.0)),
]
TURN_DEG = 3.0


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """(good, bad) recordings of the same six frames: the first with the rendered truth,
    the second with the truth of the 3 m pose turned by TURN_DEG about the camera's y."""
    tmp = tmp_path_factory.mktemp("foreign")
    frames, truths = [], []
    for n, (r, p, y, roll, off) in enumerate(POSES):
        T = facing_pose(r, p, y, roll, off)
        for k in range(3):
            frames.append(render(T, seed=10 * n + k))
            truths.append(T)
    paths = tmp / "good.h5", tmp / "bad.h5"
    for path in paths:
        with RecordingWriter(path, CameraModel(), paper_target(), with_truth=True) as w:
            for i, (f, T) in enumerate(zip(frames, truths, strict=True)):
                R = T.R
                if path.name == "bad.h5" and i >= 3:
                    R = _rot("y", TURN_DEG) @ R
                w.append(f.gray, f.distance_mm, 0.05 * i, R, T.t_mm)
    return paths


def test_common_scale_error_is_the_centroids_scale_about_their_mean_times_the_rms_radius():
    """Centroids at 1.002 x their true offsets from the pattern's centre, plus a shift
    common to all (no scale): c = 0.002 x the rms radius; a wrongly matched blob is left
    out; fewer than 4 correct matches give None. The excess subtracts the random part."""
    from types import SimpleNamespace

    cat = paper_target()
    true_uv = np.array(
        [[100.0, 80.0], [140.0, 82.0], [120.0, 130.0], [90.0, 120.0], [150.0, 125.0]]
    )
    truth = TrueImages(
        np.zeros((5, 3)), true_uv, np.full(5, 4000.0), np.full(5, 2.0), np.ones(5, bool)
    )
    centre = true_uv.mean(axis=0)
    measured = centre + 1.002 * (true_uv - centre) + [0.3, -0.2]

    def result(uv, ids):
        return SimpleNamespace(
            ok=True,
            matched=[
                SimpleNamespace(
                    centroid_uv=p, distance_mm=4000.0, catalog_id=i, centroid_sigma_px=0.05
                )
                for p, i in zip(uv, ids, strict=True)
            ],
        )

    c, random_px = common_scale_error_px(result(measured, cat.ids[:5]), truth, cat)
    r_rms = np.sqrt(((true_uv - centre) ** 2).sum(axis=1).mean())
    assert c == pytest.approx(0.002 * r_rms, rel=1e-9)
    assert random_px == pytest.approx(0.05 / np.sqrt(5))
    # the fifth blob claimed as another reflector: left out, four remain (their own fit)
    ids = list(cat.ids[:4]) + [cat.ids[6]]
    c4, _ = common_scale_error_px(result(measured, ids), truth, cat)
    t4 = true_uv[:4] - true_uv[:4].mean(axis=0)
    assert c4 == pytest.approx(0.002 * np.sqrt((t4**2).sum(axis=1).mean()), rel=1e-9)
    assert common_scale_error_px(result(measured[:3], cat.ids[:3]), truth, cat) is None
    assert common_scale_excess_px([(0.05, 0.03), (-0.05, 0.03)]) == pytest.approx(0.04)
    assert common_scale_excess_px([(0.01, 0.03)]) == 0.0
    assert math.isnan(common_scale_excess_px([]))


def test_harness_on_simulated_frames(recordings, tmp_path, capsys):
    good, bad = recordings
    ev = foreign.evaluate(good, progress=False)
    assert ev["bins"] == ["1.5 m", "3.0 m"] and ev["oracle_frames_matched"] == 6
    pose = {(p["bin"], p["run"]): p for p in ev["pose"]}
    for run in foreign.RUNS:
        s = pose[("all", run)]
        assert s["frames"] == 6 and s["no_pose"] == 0
        assert s["success_pct"] == 100.0 and s["wrong"] == 0 and s["mismatch_frames"] == 0
        assert s["median_attitude_deg"] < 0.3 and s["median_position_mm"] < 5.0
    # per-marker: correctly matched, sub-pixel, and ranged to a few mm on our simulator
    rows = [m for m in ev["markers"] if m["run"] == "pipeline"]
    assert {m["diameter_mm"] for m in rows} == {35.0, 80.0}
    assert sum(m["matched"] for m in rows) >= 6 * 6 and all(m["mismatched"] == 0 for m in rows)
    assert all(m["centroid_p90_px"] < 0.3 and abs(m["range_median_mm"]) < 5.0 for m in rows)

    # the poses are the estimate command's: the same numbers as its CSV
    out = tmp_path / "poses.csv"
    assert tofpose_main(["estimate", str(good), "--out", str(out)]) == 0
    csv_z = [float(row["z_mm"]) for row in csv.DictReader(out.open())]
    results, pipe = foreign.run_estimate(good, progress=False)
    assert [f"{r.t_mm[2]:.4f}" for r in results] == [f"{z:.4f}" for z in csv_z]
    assert not pipe.config.tracking.enabled
    _, tracked = foreign.run_estimate(good, tracking=True, progress=False)
    assert tracked.config.tracking.enabled

    # the turned truth: the 3 m frames are wrong for pipeline and oracle alike, and
    # confidently so (3 deg against a reported sigma of a few tenths)
    ev = foreign.evaluate(bad, progress=False)
    pose = {(p["bin"], p["run"]): p for p in ev["pose"]}
    for run in foreign.RUNS:
        assert pose[("1.5 m", run)]["success_pct"] == 100.0
        far = pose[("3.0 m", run)]
        assert (far["success_pct"], far["wrong"], far["confident_wrong"]) == (0.0, 3, 3)
        assert far["beyond_3sigma_pct"] == 100.0 and far["nees_over_6"] > 10.0
    att = [o.attitude_error_deg for o in ev["outcomes"]["pipeline"][3:]]
    assert att == pytest.approx([TURN_DEG] * 3, abs=0.5)

    # the command line: tables printed, every number in the JSON
    js = tmp_path / "out.json"
    assert foreign.main([str(good), str(bad), "--quiet", "--json", str(js)]) == 0
    printed = capsys.readouterr().out
    assert printed.count("| range | run ") == 6 and "conf. wrong" in printed
    doc = json.loads(js.read_text())
    assert [r["path"] for r in doc["recordings"]] == [str(good), str(bad)]
    assert "beyond_3sigma" in doc["definitions"]
    detail = doc["recordings"][1]["frames_detail"]["pipeline"]
    assert [d["wrong"] for d in detail] == [False] * 3 + [True] * 3
