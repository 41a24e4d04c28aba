"""The report CSV reads back under the current column names, whichever version wrote it:
a file of the older naming (``lab_truth_*``, ``calibrated_truth_*``), written here with
the csv module, analyses to the same statistics as the same frames written today."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from backend.services.reports.analysis import AXES, analyse
from backend.services.reports.report_csv import ReportCsvError, read_csv
from backend.services.reports.reports import CSV_COLUMNS, to_csv

REQ = {"x_mm": 6.0, "y_mm": 6.0, "z_mm": 28.3, "pitch_deg": 0.15, "yaw_deg": 0.15, "roll_deg": 0.15}
BIAS = {
    "x_mm": 2.0,
    "y_mm": -1.0,
    "z_mm": 3.0,
    "pitch_deg": 0.05,
    "yaw_deg": -0.02,
    "roll_deg": 0.01,
}


def _frames(n_sp=2, n=25) -> list[dict]:
    """Frames whose pose is the lab's reference plus ``BIAS`` and 0.01 noise, the truth
    1 unit away from the reference (what a mis-mounted bench does)."""
    rng = np.random.default_rng(7)
    rows = []
    for sp in range(n_sp):
        for k in range(n):
            r = {"setpoint_index": sp, "frame_index": k, "ok": 1}
            for a in AXES:
                ref = 100.0 * sp + 10.0
                r[f"reference_{a}"] = ref
                r[f"truth_{a}"] = ref + 1.0
                r[f"calibrated_reference_{a}"] = ref + 0.5
                r[a] = ref + BIAS[a] + rng.normal(0, 0.01)
                r[f"sigma_{a}"] = 0.01
            rows.append(r)
    return rows


def _old_csv(rows: list[dict]) -> str:
    """``rows`` as the report CSV was written before the rename."""
    old = {f"reference_{a}": f"lab_truth_{a}" for a in AXES}
    old |= {f"calibrated_reference_{a}": f"calibrated_truth_{a}" for a in AXES}
    header = [old.get(c, c) for c in CSV_COLUMNS]
    assert any(h.startswith("lab_truth_") for h in header)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow(["" if r.get(c) is None else r[c] for c in CSV_COLUMNS])
    return buf.getvalue()


def test_the_csv_names_the_lab_reference_reference_and_the_rendered_pose_truth():
    header = next(csv.reader(io.StringIO(to_csv([]))))
    for a in AXES:
        assert f"truth_{a}" in header
        assert f"reference_{a}" in header
        assert f"calibrated_reference_{a}" in header
    assert not [h for h in header if "lab_truth" in h or "calibrated_truth" in h]


@pytest.mark.parametrize("reference", ["lab", "calibrated", "truth"])
def test_an_old_csv_analyses_as_the_same_frames_written_today(reference):
    rows = _frames()
    new = read_csv(to_csv(rows))
    old = read_csv(_old_csv(rows))
    assert set(old[0]) == set(new[0]) == set(CSV_COLUMNS)
    got_old, got_new = analyse(old, REQ, reference), analyse(new, REQ, reference)
    # NaN (a statistic undefined here) compares unequal to itself: compare the JSON text
    assert json.dumps(got_old, sort_keys=True) == json.dumps(got_new, sort_keys=True)
    # and the statistics are those of the frames: bias against the lab's reference is
    # BIAS, against the calibrated one BIAS - 0.5, against the truth BIAS - 1
    shift = {"lab": 0.0, "calibrated": 0.5, "truth": 1.0}[reference]
    for a in AXES:
        bias = got_old["overall"]["axes"][a]["bias"]
        assert bias == pytest.approx(BIAS[a] - shift, abs=0.01), (a, bias)


def test_a_file_with_both_names_keeps_the_current_one_and_empty_cells_read_as_none():
    text = "setpoint_index,ok,reference_x_mm,lab_truth_x_mm,truth_x_mm\n0,1,5.0,9.0,\n"
    (row,) = read_csv(text)
    assert row["reference_x_mm"] == "5.0" and row["truth_x_mm"] is None


def test_a_csv_that_is_not_a_report_is_named():
    with pytest.raises(ReportCsvError, match="no setpoint_index, ok column"):
        read_csv("a,b\n1,2\n")
