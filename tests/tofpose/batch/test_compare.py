"""Comparing two runs: identical runs differ by nothing; a changed calibration shows up
as the shift it causes; runs of different recordings or files that are not pose CSVs
are named."""

from __future__ import annotations

import json

import pytest

from tofpose.batch.compare import CompareError, compare_runs
from tofpose.cli import main
from tofpose.core.camera import CameraModel


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmp")
    rec = d / "r.h5"
    assert (
        main(["simulate", "--scenario", "stability-697", "--frames", "6", "--out", str(rec)]) == 0
    )
    a, b = d / "a" / "r.csv", d / "b" / "r.csv"
    a.parent.mkdir()
    b.parent.mkdir()
    assert main(["estimate", str(rec), "--out", str(a)]) == 0
    # a calibration whose focal length is 1 % long: the target reads ~1 % farther
    cam = CameraModel()
    doc = json.loads(cam.to_json())
    doc["fx"], doc["fy"] = cam.fx * 1.01, cam.fy * 1.01
    cam_path = d / "cam.json"
    cam_path.write_text(json.dumps(doc))
    assert main(["estimate", str(rec), "--out", str(b), "--camera", str(cam_path)]) == 0
    return d, a, b


def test_a_run_against_itself_differs_by_nothing(runs, tmp_path):
    _, a, _ = runs
    s = compare_runs(str(a), str(a), tmp_path)
    r = s["recordings"]["r"]
    assert r["ok_a"] == r["ok_b"] == 6 and r["gained"] == r["lost"] == 0
    assert r["attitude_diff_deg"]["max"] == 0.0 and r["position_diff_mm"]["max"] == 0.0
    assert (tmp_path / "compare.png").stat().st_size > 0
    assert len((tmp_path / "compare.csv").read_text().splitlines()) == 7


def test_a_changed_calibration_shows_its_shift(runs, tmp_path):
    d, _, _ = runs
    assert main(["compare", str(d / "a"), str(d / "b"), "--out", str(tmp_path)]) == 0
    r = json.loads((tmp_path / "compare.json").read_text())["recordings"]["r"]
    # bearings 1 % narrower: lateral offsets shrink, the fitted range is held by the
    # measured ranges; the pose moves by millimetres, not by nothing
    assert r["position_diff_mm"]["p50"] > 0.05
    assert r["ok_b"] == 6


def test_bad_runs_are_named(runs, tmp_path):
    d, a, _ = runs
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,ok\n0,1\n")
    with pytest.raises(CompareError, match="missing column x_mm"):
        compare_runs(str(a), str(bad), tmp_path / "o")
    with pytest.raises(CompareError, match="no such file"):
        compare_runs(str(a), str(tmp_path / "none.csv"), tmp_path / "o")
    short = tmp_path / "short.csv"
    short.write_text("\n".join(a.read_text().splitlines()[:3]) + "\n")
    with pytest.raises(CompareError, match="different frames"):
        compare_runs(str(a), str(short), tmp_path / "o")
