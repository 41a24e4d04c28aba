"""A study cell's verdict against its requirements, on constructed frames with known
errors: a cell just inside a requirement passes with the deciding number, one just
outside fails naming the axis and its share; frames without a pose count against the
cell and are named by their reason (or as having none); the study's paragraph names the
count and the worst cell."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tofpose.study.study_rows import column_dict, frame_row, table
from tofpose.study.axis_errors import requirement_axis_errors
from tofpose.study.spec import StudyRequirements, StudySpec
from tofpose.study.summary import summarise
from tofpose.study.verdict import NO_REASON, judge_cell

N = 20  # frames per cell: p95 (inverted_cdf) is the 19th smallest |error|


def _cell(cell: int, pitches, dz=0.0, missing=(), reason="") -> list[dict]:
    rows = [frame_row(cell, i, pitch_deg=p, dz_mm=dz) for i, p in enumerate(pitches)]
    for i in missing:
        rows[i] = frame_row(cell, i, ok=False, reason=reason)
    return rows


def _judge(rows, req=None):
    cols = column_dict(rows)
    return judge_cell(
        requirement_axis_errors(cols), list(cols["reason"]), req or StudyRequirements()
    )


def test_the_axis_errors_are_the_facing_euler_and_position_errors_put_in():
    cols = column_dict(_cell(0, [0.149, -0.3], dz=-28.4, missing=()))
    err = requirement_axis_errors(cols)
    np.testing.assert_allclose(err[:, 3], [0.149, -0.3], atol=1e-9)  # pitch
    np.testing.assert_allclose(err[:, 4:], 0.0, atol=1e-9)  # yaw, roll
    np.testing.assert_allclose(err[:, 2], -28.4)  # z
    cols = column_dict([frame_row(0, 0, ok=False, reason="x")])
    assert np.isnan(requirement_axis_errors(cols)).all()


def test_a_cell_just_inside_passes_and_just_outside_fails_with_the_deciding_number():
    inside = _judge(_cell(0, [0.149] * N))
    assert inside.passed is True
    assert inside.deciding == "pitch_deg"
    pitch = dict((j.axis, j) for j in inside.axes)["pitch_deg"]
    assert pitch.value == pytest.approx(0.149, abs=1e-9) and pitch.within_pct == 100.0
    assert inside.text.startswith("PASS")
    assert "pitch p95 |error| 0.149 deg = 99 % of 0.15 deg" in inside.text
    assert inside.main_failure is None and inside.within_all_pct == 100.0

    outside = _judge(_cell(0, [0.151] * N))
    assert outside.passed is False and outside.deciding == "pitch_deg"
    assert outside.text == "FAIL: pitch p95 |error| 0.151 deg = 101 % of 0.15 deg"
    assert outside.main_failure == f"pitch beyond 0.15 deg ({N} of {N} frames)"

    # position: z 28.2 mm is inside 28.3 mm, 28.4 mm outside
    assert _judge(_cell(0, [0.0] * N, dz=28.2)).passed is True
    z = _judge(_cell(0, [0.0] * N, dz=-28.4))
    assert z.passed is False and z.deciding == "z_mm"
    assert "z p95 |error| 28.4 mm = 100.4 % of 28.3 mm" in z.text


def test_the_percentile_is_the_share_of_frames_within():
    # 19 of 20 frames within (95 %): p95 is the 19th smallest, inside; 18 of 20: outside
    assert _judge(_cell(0, [0.1] * 19 + [0.9])).passed is True
    two_out = _judge(_cell(0, [0.1] * 18 + [0.9, 0.8]))
    assert two_out.passed is False
    assert "pitch p95 |error| 0.8 deg" in two_out.text
    assert two_out.main_failure == f"pitch beyond 0.15 deg (2 of {N} frames)"
    # the same cell against every frame (p100): the largest error decides
    strict = _judge(_cell(0, [0.1] * 19 + [0.9]), StudyRequirements(percentile=100.0))
    assert strict.passed is False and "p100 |error| 0.9 deg" in strict.text


def test_frames_without_a_pose_count_against_the_cell_and_are_named():
    too_many = _judge(_cell(0, [0.05] * N, missing=(3, 7), reason="too few blobs: 2 < 3"))
    assert too_many.passed is False and too_many.no_pose == 2
    assert too_many.text == (
        "FAIL: no pose in 2 of 20 frames (10.0 %), more than the 5 % a p95 requirement allows"
    )
    assert too_many.main_failure == f"no pose: too few blobs (2 of {N} frames)"
    # one refused frame in 20 is within the 5 %; its empty reason is said in words
    blank = _judge(_cell(0, [0.05] * N, missing=(4,), reason=""))
    assert blank.passed is True
    assert blank.failure_modes == {NO_REASON: 1}
    assert blank.main_failure == f"{NO_REASON} (1 of {N} frames)"


def test_the_summary_leads_with_the_study_verdict_naming_the_worst_cell():
    spec = StudySpec.from_dict(
        {
            "name": "known",
            "frames_per_cell": N,
            "grid": {"range_m": [3, 5], "physics": ["ideal", "all"]},
        }
    )
    rows = (
        _cell(0, [0.149] * N)
        + _cell(1, [0.151] * N)
        + _cell(2, [0.05] * N, missing=(3, 7), reason="too few blobs: 2 < 3")
        + _cell(3, [0.0] * N, dz=10.0)
    )
    summary = summarise(spec, table(rows))
    assert [c["verdict"]["passed"] for c in summary["cells"]] == [True, False, False, True]
    v = summary["verdict"]
    assert (v["cells_passed"], v["cells_judged"], v["passed"], v["worst_cell"]) == (2, 4, False, 2)
    assert v["text"].startswith(
        "FAIL: 2 of 4 cells meet the requirements (x and y 6 mm, z 28.3 mm, pitch, yaw and "
        "roll 0.15 deg, each in at least 95 % of a cell's frames). The worst is cell 2 (5 m,"
    )
    assert "no pose in 2 of 20 frames" in v["text"]
    assert v["text"].endswith(f"main failure: no pose: too few blobs (2 of {N} frames).")
    assert summary["requirements"]["z_mm"] == 28.3
    # looser requirements: every cell passes
    loose = StudySpec.from_dict(
        {**spec.to_dict(), "requirements": {"pitch_deg": 0.2, "percentile": 90}}
    )
    assert summarise(loose, table(rows))["verdict"]["text"].startswith("PASS: all 4 cells meet")
